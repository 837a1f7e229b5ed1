// WebGL2 ray marcher of the baked grid: the same volume rendering as the Python renderer (DESIGN 1.1):
// density = exp(min(logit, clamp)) with the logit trilinearly interpolated, uniform steps of the reference
// spacing in the box's normalised frame, front-to-back compositing over white, stopping when opaque.
"use strict";

const S3DGL = (() => {
  const VERT = `#version 300 es
  void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
  }`;

  const FRAG = `#version 300 es
  precision highp float;
  precision highp sampler3D;
  uniform sampler3D grid;
  uniform sampler3D occupancy;
  uniform vec3 origin;      // camera centre, normalised frame
  uniform vec3 right, up, back;
  uniform vec2 size;        // pixels
  uniform float focal;      // pixels
  uniform vec3 halfUnit;    // the box is [-halfUnit, halfUnit]
  uniform float stepLen;
  uniform float blocks;     // occupancy texels per axis
  uniform vec2 logitRange;
  uniform float clampLogit;
  uniform float background;
  out vec4 colour;
  const int MAX_STEPS = 1024;
  void main() {
    vec2 c = (gl_FragCoord.xy - 0.5 * size) / focal;   // gl_FragCoord is bottom-up: +y is up
    vec3 d = normalize(c.x * right + c.y * up - back);
    vec3 inv = 1.0 / mix(d, vec3(1e-9), lessThan(abs(d), vec3(1e-9)));
    vec3 t0 = (-halfUnit - origin) * inv, t1 = (halfUnit - origin) * inv;
    float near = max(max(max(min(t0.x, t1.x), min(t0.y, t1.y)), min(t0.z, t1.z)), 0.0);
    float far = min(min(max(t0.x, t1.x), max(t0.y, t1.y)), max(t0.z, t1.z));
    vec3 acc = vec3(0.0);
    float trans = 1.0;
    if (near < far) {
      for (int i = 0; i < MAX_STEPS; i++) {
        float t = near + (float(i) + 0.5) * stepLen;
        if (t >= far || trans < 1e-3) break;
        vec3 uvw = ((origin + t * d) / halfUnit + 1.0) * 0.5;
        if (texture(occupancy, uvw).r == 0.0) {  // jump to the first sample past this empty block
          vec3 lo = floor(uvw * blocks) / blocks, hi = lo + 1.0 / blocks;
          vec3 du = d / (2.0 * halfUnit);
          vec3 te = (mix(lo, hi, greaterThan(du, vec3(0.0))) - uvw) / mix(du, vec3(1e-9), lessThan(abs(du), vec3(1e-9)));
          te = mix(te, vec3(1e9), lessThan(abs(du), vec3(1e-9)));
          float exit = t + min(min(te.x, te.y), te.z);
          i = max(i, int(ceil((exit - near) / stepLen - 0.5)) - 1);
          continue;
        }
        vec4 v = texture(grid, uvw);
        float logit = logitRange.x + v.a * (logitRange.y - logitRange.x);
        float alpha = 1.0 - exp(-exp(min(logit, clampLogit)) * stepLen);
        acc += trans * alpha * v.rgb;
        trans *= 1.0 - alpha;
      }
    }
    colour = vec4(acc + trans * background, 1.0);
  }`;

  const BLOCK = 4;          // cells per occupancy texel along each axis
  const VISIBLE_ALPHA = 1e-4;  // a cell whose one-step opacity is below this counts as empty

  // (ob^3) uint8, x fastest: 255 where the block or one of its 26 neighbours has a visible cell
  function occupancy(grid, ob) {
    const h = grid.header, b = h.res, c = grid.cells;
    const [lo, hi] = h.logit_range;
    const aMin = Math.ceil(((Math.log(-Math.log1p(-VISIBLE_ALPHA) / h.step) - lo) / (hi - lo)) * 255);
    const raw = new Uint8Array(ob * ob * ob);
    for (let z = 0; z < b; z++)
      for (let y = 0; y < b; y++)
        for (let x = 0; x < b; x++)
          if (c[4 * ((z * b + y) * b + x) + 3] >= aMin)
            raw[((z / BLOCK | 0) * ob + (y / BLOCK | 0)) * ob + (x / BLOCK | 0)] = 255;
    const out = new Uint8Array(ob * ob * ob);
    for (let z = 0; z < ob; z++)
      for (let y = 0; y < ob; y++)
        for (let x = 0; x < ob; x++) {
          let any = 0;
          for (let dz = -1; dz <= 1 && !any; dz++)
            for (let dy = -1; dy <= 1 && !any; dy++)
              for (let dx = -1; dx <= 1 && !any; dx++) {
                const X = x + dx, Y = y + dy, Z = z + dz;
                if (X >= 0 && Y >= 0 && Z >= 0 && X < ob && Y < ob && Z < ob) any = raw[(Z * ob + Y) * ob + X];
              }
          out[(z * ob + y) * ob + x] = any;
        }
    return out;
  }

  function compile(gl, type, src) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(s));
    return s;
  }

  // canvas + parsed grid -> {draw(azimuth, elevation, distance), gl}; null when WebGL2 is missing.
  function create(canvas, grid) {
    const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false });
    if (!gl) return null;
    if (canvas.s3dDispose) canvas.s3dDispose();  // the previous scene's program and textures on this canvas
    const prog = gl.createProgram();
    gl.attachShader(prog, compile(gl, gl.VERTEX_SHADER, VERT));
    gl.attachShader(prog, compile(gl, gl.FRAGMENT_SHADER, FRAG));
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error("program: " + gl.getProgramInfoLog(prog));
    const h = grid.header, b = h.res;
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_3D, tex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage3D(gl.TEXTURE_3D, 0, gl.RGBA8, b, b, b, 0, gl.RGBA, gl.UNSIGNED_BYTE, grid.cells);
    for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_3D, p, gl.LINEAR);
    for (const p of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T, gl.TEXTURE_WRAP_R])
      gl.texParameteri(gl.TEXTURE_3D, p, gl.CLAMP_TO_EDGE);
    const occ = gl.createTexture();
    const ob = Math.ceil(b / BLOCK);
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_3D, occ);
    gl.texImage3D(gl.TEXTURE_3D, 0, gl.R8, ob, ob, ob, 0, gl.RED, gl.UNSIGNED_BYTE, occupancy(grid, ob));
    for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_3D, p, gl.NEAREST);
    for (const p of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T, gl.TEXTURE_WRAP_R])
      gl.texParameteri(gl.TEXTURE_3D, p, gl.CLAMP_TO_EDGE);
    gl.activeTexture(gl.TEXTURE0);
    gl.useProgram(prog);
    const u = (name) => gl.getUniformLocation(prog, name);
    const frame = S3DGrid.frame(h);
    gl.uniform1i(u("grid"), 0);
    gl.uniform1i(u("occupancy"), 1);
    gl.uniform1f(u("blocks"), ob);
    gl.uniform3fv(u("halfUnit"), frame.halfUnit);
    gl.uniform1f(u("stepLen"), h.step);
    gl.uniform2fv(u("logitRange"), h.logit_range);
    gl.uniform1f(u("clampLogit"), h.density_clamp);
    gl.uniform1f(u("background"), h.background);
    const vao = gl.createVertexArray();

    function draw(azimuth, elevation, distance) {
      const w = canvas.width, hgt = canvas.height;
      const cam = S3DGrid.camera(h, azimuth, elevation, distance);
      gl.viewport(0, 0, w, hgt);
      gl.uniform3fv(u("origin"), cam.eye.map((v, k) => (v - frame.centre[k]) / frame.scale));
      gl.uniform3fv(u("right"), cam.right);
      gl.uniform3fv(u("up"), cam.up);
      gl.uniform3fv(u("back"), cam.back);
      gl.uniform2f(u("size"), w, hgt);
      gl.uniform1f(u("focal"), (0.5 * w) / Math.tan((0.5 * h.orbit.fov_deg * Math.PI) / 180));
      gl.bindVertexArray(vao);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    }
    canvas.s3dDispose = () => {
      gl.deleteTexture(tex); gl.deleteTexture(occ); gl.deleteProgram(prog); gl.deleteVertexArray(vao);
      canvas.s3dDispose = null;
    };
    return { draw, gl };
  }

  return { create };
})();
