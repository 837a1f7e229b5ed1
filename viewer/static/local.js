// A snapshot PNG decoded in the browser, with no server work (docs/onnx-contract.md; the same steps as
// viewer/decode.py for a snapshot file): its metadata line from the PNG tEXt chunk "snapshot3d", a file
// written at k times the snapshot's size (`embed` writes 4x) shrunk to 380x380 by the means of its k x k
// squares, rounded as OpenCV's INTER_AREA rounds them (scanner/snapfile.py `snapshot_pixels`), the
// restore graph in onnxruntime-web (vendored, WebAssembly), the least-squares unspread and 8-bit
// rounding, then the field baked into a grid with the project and field graphs exactly as viewer/bake.py
// does (a coarse pass at B/4, then the cells of the surface's shell at B), and the grid packed as the
// server's /grid packs it (viewer/gridfile.py), ready for S3DGL.
"use strict";

const S3DLocal = (() => {
  const SIZE = 380, GRID = 95, SECRET_CHANNELS = 8, C_MAX = 12, BAKE = 96, COARSE = 4;
  const OCC_ALPHA = 0.01, DENSE_ALPHA = 0.5, STEPS_PER_BOX = 192, DENSITY_CLAMP = 15, LOGIT_FLOOR = -10;
  const ORBIT_ELEVATION = 20, ORBIT_FOV = 40, FILE_CODEC = "hinet-3", MAX_SCALE = 8;

  // ArrayBuffer of a PNG -> the text of its tEXt chunk `keyword`, or null
  function pngText(buffer, keyword) {
    const b = new Uint8Array(buffer), v = new DataView(buffer);
    const sig = [137, 80, 78, 71, 13, 10, 26, 10];
    if (b.length < 8 || sig.some((x, i) => b[i] !== x)) return null;
    for (let p = 8; p + 8 <= b.length;) {
      const n = v.getUint32(p), type = String.fromCharCode(...b.subarray(p + 4, p + 8));
      if (type === "tEXt") {
        const data = b.subarray(p + 8, p + 8 + n), z = data.indexOf(0);
        if (z > 0 && new TextDecoder("latin1").decode(data.subarray(0, z)) === keyword)
          return new TextDecoder("latin1").decode(data.subarray(z + 1));
      }
      if (type === "IEND") break;
      p += 12 + n;
    }
    return null;
  }

  // ArrayBuffer of a PNG -> [width, height] from its IHDR chunk (which a PNG starts with), or null
  function pngSize(buffer) {
    const b = new Uint8Array(buffer), v = new DataView(buffer);
    if (b.length < 24 || String.fromCharCode(...b.subarray(12, 16)) !== "IHDR") return null;
    return [v.getUint32(16), v.getUint32(20)];
  }

  // k times the snapshot's size, square, k in 1..MAX_SCALE: the file medium's own files; else 0
  function fileScale(width, height) {
    const k = width / SIZE;
    return width === height && Number.isInteger(k) && k >= 1 && k <= MAX_SCALE ? k : 0;
  }

  // RGBA bytes of a (k SIZE)^2 image -> planar RGB float32 (3, SIZE, SIZE) in [0, 1]: the 8-bit means of
  // its k x k squares, ties rounded as OpenCV's INTER_AREA does (half up for k = 2, else half to even)
  function squareMeans(px, k) {
    const x = new Float32Array(3 * SIZE * SIZE), area = k * k, w = k * SIZE;
    for (let y = 0; y < SIZE; y++)
      for (let xx = 0; xx < SIZE; xx++)
        for (let c = 0; c < 3; c++) {
          let sum = 0;
          for (let dy = 0; dy < k; dy++)
            for (let dx = 0; dx < k; dx++) sum += px[4 * ((y * k + dy) * w + xx * k + dx) + c];
          let q = Math.floor(sum / area);
          const twice = 2 * (sum - q * area);
          if (twice > area || (twice === area && (k === 2 || q % 2 === 1))) q += 1;
          x[c * SIZE * SIZE + y * SIZE + xx] = q / 255;
        }
    return x;
  }

  // the metadata line (contract section 1) -> {version, codec, box, orbit, target, planes, strength, decoder,
  // head}; head: whether the scene has a head of its own (h=), which this page leaves to the server
  function parseMeta(text) {
    const parts = text.split("|");
    if (parts.length < 2 || !/^S3D\d+$/.test(parts[0])) throw new Error("not a snapshot3d metadata line");
    const f = {};
    for (const p of parts.slice(2)) { const [k, v] = p.split("="); f[k] = v.split(",").map(Number); }
    return { version: Number(parts[0].slice(3)), codec: parts[1], box: f.b, orbit: f.o, target: f.t,
             planes: f.p, strength: f.s ? f.s[0] : 1, decoder: `tri-dec-${f.d ? f.d[0] : 1}`, head: "h" in f };
  }

  // (GRID, R) spread matrix U and its pseudo-inverse P = (U^T U)^-1 U^T (R, GRID), float64 row-major
  function unspreadMatrix(r) {
    const u = new Float64Array(GRID * r);
    for (let i = 0; i < GRID; i++) {
      const pos = (i * (r - 1)) / (GRID - 1), j = Math.min(Math.floor(pos), r - 2), w = pos - j;
      u[i * r + j] = 1 - w; u[i * r + j + 1] = w;
    }
    const a = new Float64Array(r * 2 * r);  // [U^T U | I], Gauss-Jordan
    for (let x = 0; x < r; x++) {
      for (let y = 0; y < r; y++) { let s = 0; for (let i = 0; i < GRID; i++) s += u[i * r + x] * u[i * r + y]; a[x * 2 * r + y] = s; }
      a[x * 2 * r + r + x] = 1;
    }
    for (let c = 0; c < r; c++) {
      let piv = c;
      for (let k = c + 1; k < r; k++) if (Math.abs(a[k * 2 * r + c]) > Math.abs(a[piv * 2 * r + c])) piv = k;
      if (piv !== c) for (let k = 0; k < 2 * r; k++) { const t = a[c * 2 * r + k]; a[c * 2 * r + k] = a[piv * 2 * r + k]; a[piv * 2 * r + k] = t; }
      const d = a[c * 2 * r + c];
      for (let k = 0; k < 2 * r; k++) a[c * 2 * r + k] /= d;
      for (let row = 0; row < r; row++) {
        if (row === c) continue;
        const m = a[row * 2 * r + c];
        if (m !== 0) for (let k = 0; k < 2 * r; k++) a[row * 2 * r + k] -= m * a[c * 2 * r + k];
      }
    }
    const p = new Float64Array(r * GRID);
    for (let x = 0; x < r; x++)
      for (let i = 0; i < GRID; i++) { let s = 0; for (let y = 0; y < r; y++) s += a[x * 2 * r + r + y] * u[i * r + y]; p[x * GRID + i] = s; }
    return p;
  }

  // secret (24 * 95 * 95) -> planes (3, C_MAX, R, R) float32, zero-padded, rounded to 8 bits
  function unspread(secret, r, c, strength) {
    const p = unspreadMatrix(r), out = new Float32Array(3 * C_MAX * r * r), tmp = new Float64Array(r * GRID);
    for (let k = 0; k < 3; k++)
      for (let ch = 0; ch < c; ch++) {
        const s = secret.subarray((k * SECRET_CHANNELS + ch) * GRID * GRID, (k * SECRET_CHANNELS + ch + 1) * GRID * GRID);
        for (let x = 0; x < r; x++)        // tmp = P S
          for (let j = 0; j < GRID; j++) { let acc = 0; for (let i = 0; i < GRID; i++) acc += p[x * GRID + i] * s[i * GRID + j]; tmp[x * GRID + j] = acc / strength; }
        const base = (k * C_MAX + ch) * r * r;
        for (let x = 0; x < r; x++)        // X = (P S) P^T, then 8-bit rounding
          for (let y = 0; y < r; y++) {
            let acc = 0;
            for (let j = 0; j < GRID; j++) acc += tmp[x * GRID + j] * p[y * GRID + j];
            const code = Math.round(((Math.min(Math.max(acc, -1), 1) + 1) / 2) * 255);
            out[base + x * r + y] = Math.fround(Math.fround(code / 255) * 2 - 1);
          }
      }
    return out;
  }

  function interp(b, r) {  // (b, r) bilinear weights of cell centres over texels (contract section 3)
    const m = new Float32Array(b * r);
    for (let i = 0; i < b; i++) {
      const uc = ((i + 0.5) / b) * 2 - 1, t = Math.min(Math.max(((uc + 1) / 2) * (r - 1), 0), r - 1);
      const j = Math.min(Math.floor(t), r - 2);
      m[i * r + j] += 1 - (t - j); m[i * r + j + 1] += t - j;
    }
    return m;
  }

  // field at cells (flat ix, iy, iz triples) of a res^3 grid -> {logit, rgb}
  async function gridField(s, planes, r, res, cells) {
    const ort = window.ort, n = cells.length / 3;
    const tables = (await s.project.run({ planes: new ort.Tensor("float32", planes, [3, C_MAX, r, r]),
                                           interp: new ort.Tensor("float32", interp(res, r), [res, r]) })).tables;
    const logit = new Float32Array(n), rgb = new Float32Array(3 * n), chunk = 65536;
    for (let s0 = 0; s0 < n; s0 += chunk) {
      const m = Math.min(chunk, n - s0), rows = new BigInt64Array(3 * m);
      for (let q = 0; q < m; q++) {
        const ix = cells[3 * (s0 + q)], iy = cells[3 * (s0 + q) + 1], iz = cells[3 * (s0 + q) + 2];
        rows[3 * q] = BigInt(iy * res + ix); rows[3 * q + 1] = BigInt(iz * res + ix); rows[3 * q + 2] = BigInt(iz * res + iy);
      }
      const out = await s.field.run({ tables, rows: new ort.Tensor("int64", rows, [m, 3]) });
      logit.set(out.density_logit.data, s0);
      rgb.set(out.rgb.data, 3 * s0);
    }
    return { logit, rgb };
  }

  function neighbourhood(mask, n, isMax) {  // 3x3x3 dilate (isMax) or erode of a bool grid, outside = false
    const out = new Uint8Array(n * n * n);
    for (let x = 0; x < n; x++)
      for (let y = 0; y < n; y++)
        for (let z = 0; z < n; z++) {
          let v = isMax ? 0 : 1;
          for (let dx = -1; dx <= 1; dx++)
            for (let dy = -1; dy <= 1; dy++)
              for (let dz = -1; dz <= 1; dz++) {
                const X = x + dx, Y = y + dy, Z = z + dz;
                const m = X >= 0 && Y >= 0 && Z >= 0 && X < n && Y < n && Z < n ? mask[(X * n + Y) * n + Z] : 0;
                v = isMax ? v | m : v & m;
              }
          out[(x * n + y) * n + z] = v;
        }
    return out;
  }

  // the bake of viewer/bake.py -> grid values [ix, iy, iz] (logit, r, g, b) as Float32Array (B^3 * 4)
  async function bake(s, planes, r, step) {
    const nc = BAKE / COARSE, ncells = nc * nc * nc;
    const all = new Int32Array(3 * ncells);
    for (let i = 0; i < ncells; i++) { all[3 * i] = (i / (nc * nc)) | 0; all[3 * i + 1] = ((i / nc) | 0) % nc; all[3 * i + 2] = i % nc; }
    const coarse = await gridField(s, planes, r, nc, all);
    const occ = new Uint8Array(ncells), dense = new Uint8Array(ncells);
    for (let i = 0; i < ncells; i++) {
      const alpha = -Math.expm1(-Math.exp(coarse.logit[i]) * step);
      occ[i] = alpha > OCC_ALPHA; dense[i] = alpha > DENSE_ALPHA;
    }
    const dil = neighbourhood(occ, nc, true), ero = neighbourhood(dense, nc, false);
    const b = BAKE, grid = new Float32Array(b * b * b * 4), fine = [];
    for (let x = 0; x < b; x++)
      for (let y = 0; y < b; y++)
        for (let z = 0; z < b; z++) {
          const ci = (((x / COARSE) | 0) * nc + ((y / COARSE) | 0)) * nc + ((z / COARSE) | 0), g = ((x * b + y) * b + z) * 4;
          grid[g] = coarse.logit[ci];
          grid[g + 1] = coarse.rgb[3 * ci]; grid[g + 2] = coarse.rgb[3 * ci + 1]; grid[g + 3] = coarse.rgb[3 * ci + 2];
          if (dil[ci] && !ero[ci]) fine.push(x, y, z);
        }
    const f = await gridField(s, planes, r, b, Int32Array.from(fine));
    for (let q = 0; q < fine.length / 3; q++) {
      const g = ((fine[3 * q] * b + fine[3 * q + 1]) * b + fine[3 * q + 2]) * 4;
      grid[g] = f.logit[q]; grid[g + 1] = f.rgb[3 * q]; grid[g + 2] = f.rgb[3 * q + 1]; grid[g + 3] = f.rgb[3 * q + 2];
    }
    return { grid, evaluated: ncells + fine.length / 3 };
  }

  // grid [ix, iy, iz] (logit, rgb) -> the /grid packing (viewer/gridfile.py): rgba uint8, x fastest
  function pack(grid, header) {
    const b = BAKE, cells = new Uint8Array(b * b * b * 4);
    let hi = LOGIT_FLOOR + 1;
    for (let i = 0; i < b * b * b; i++) hi = Math.max(hi, Math.min(Math.max(grid[4 * i], LOGIT_FLOOR), DENSITY_CLAMP));
    const lo = LOGIT_FLOOR, f32 = Math.fround;
    for (let x = 0; x < b; x++)
      for (let y = 0; y < b; y++)
        for (let z = 0; z < b; z++) {
          const g = ((x * b + y) * b + z) * 4, c = ((z * b + y) * b + x) * 4;
          const l = Math.min(Math.max(grid[g], lo), DENSITY_CLAMP);
          for (let k = 0; k < 3; k++) cells[c + k] = Math.round(Math.min(Math.max(grid[g + 1 + k], 0), 1) * 255);
          cells[c + 3] = Math.round(f32(f32(l - lo) / f32(hi - lo)) * 255);
        }
    header.logit_range = [lo, hi];
    return cells;
  }

  // the restore graph, and the project and field graphs of the decoder the scene was fitted for (a
  // snapshot names it in its metadata's d= field; none: tri-dec-1)
  const sessions = {};
  async function models(decoder) {
    if (!sessions[decoder]) {
      const ort = window.ort;
      ort.env.wasm.wasmPaths = "/static/vendor/onnxruntime-web/";
      ort.env.wasm.numThreads = 1;
      const opt = { executionProviders: ["wasm"] };
      const [restore, project, field] = await Promise.all(["restore", `project-${decoder}`, `field-${decoder}`].map(
        (k) => ort.InferenceSession.create(`/v1/models/${k}.onnx`, opt)));
      sessions[decoder] = { restore, project, field };
    }
    return sessions[decoder];
  }

  // a snapshot file this page can decode by itself: a PNG with its metadata line, file medium, at 1 to
  // MAX_SCALE times the snapshot's size (any other size, e.g. a resized copy, goes to the server, which
  // finds the snapshot's grid in it)
  async function readable(file) {
    if (!window.ort || !/\.png$/i.test(file.name || "") && file.type !== "image/png") return null;
    const buffer = await file.arrayBuffer();
    const text = pngText(buffer, "snapshot3d"), size = pngSize(buffer);
    if (!text || !size || !fileScale(...size)) return null;
    const meta = parseMeta(text);
    return meta.codec === FILE_CODEC && meta.version === 1 && meta.planes && meta.box && !meta.head ? { meta, text } : null;
  }

  async function decode(file, meta, progress = () => {}) {
    const t0 = performance.now();
    const bitmap = await createImageBitmap(file, { colorSpaceConversion: "none", premultiplyAlpha: "none" });
    const k = fileScale(bitmap.width, bitmap.height);
    if (!k) throw new Error(`${bitmap.width}x${bitmap.height} is not a snapshot file's size (${SIZE}x${SIZE} times 1 to ${MAX_SCALE})`);
    const canvas = document.createElement("canvas");
    canvas.width = canvas.height = k * SIZE;
    const ctx = canvas.getContext("2d", { willReadFrequently: true });
    ctx.drawImage(bitmap, 0, 0);
    const x = squareMeans(ctx.getImageData(0, 0, k * SIZE, k * SIZE, { colorSpace: "srgb" }).data, k);
    progress("Loading the models…");
    const s = await models(meta.decoder);
    const t1 = performance.now();
    progress("Restoring the planes…");
    const secret = (await s.restore.run({ snapshot: new window.ort.Tensor("float32", x, [1, 3, SIZE, SIZE]) })).secret.data;
    const [r, c] = meta.planes;
    const planes = unspread(secret, r, c, meta.strength);
    const t2 = performance.now();
    progress("Baking the scene…");
    const lo = meta.box.slice(0, 3), hi = meta.box.slice(3, 6);
    const half = lo.map((v, k) => (hi[k] - v) / 2), scale = Math.max(...half);
    const step = (2 * Math.hypot(...half.map((h) => h / scale))) / STEPS_PER_BOX;
    const { grid, evaluated } = await bake(s, planes, r, step);
    const target = meta.target || lo.map((v, k) => (v + hi[k]) / 2);
    const orbit = meta.orbit ? { radius: meta.orbit[0], elevation_deg: meta.orbit[1], fov_deg: meta.orbit[2], target }
      : { radius: Math.hypot(...lo.map((v, k) => hi[k] - v)), elevation_deg: ORBIT_ELEVATION, fov_deg: ORBIT_FOV, target };
    const header = { res: BAKE, box: [lo, hi], orbit, step, density_clamp: DENSITY_CLAMP, background: 1.0,
                     world_up: [0, 0, 1] };
    const cells = pack(grid, header);
    const t3 = performance.now();
    return { header, cells, evaluated,
             timings_ms: { load: Math.round(t1 - t0), restore: Math.round(t2 - t1), bake: Math.round(t3 - t2) } };
  }

  return { readable, decode, pngText, pngSize, parseMeta, squareMeans };
})();
