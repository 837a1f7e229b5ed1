// The page: upload a photo (progress), then turn the decoded scene. WebGL2 renders the baked grid in the
// browser; without WebGL2 the page shows frames rendered by the server (/render). window.snapshot3d
// exposes the state for tests and for measuring frame rates.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);
  const state = { mode: null, sceneId: null, header: null, azimuth: 0, elevation: 20, distance: 1, radius: 1,
                  frames: 0, ready: false, error: null, firstViewMs: null, movingSize: 190, movingChosen: false };
  window.snapshot3d = state;
  let renderer = null, dirty = false, started = 0, moving = 0, settle = null;
  const FULL = 380, MOVING_MIN = 160, TARGET_FPS = 30;
  // drawing-buffer size at rest (FULL), and while a finger moves (state.movingSize): chosen per device when a
  // scene opens (chooseMovingSize), FULL where this GPU draws FULL at TARGET_FPS, else fewer rays

  // while the pose changes, draw at state.movingSize; 200 ms after the last change, once more at FULL
  function interacting() {
    moving = performance.now();
    clearTimeout(settle);
    settle = setTimeout(() => { moving = 0; requestDraw(); }, 200);
  }

  function status(text, isError = false) {
    $("status").textContent = text;
    $("status").classList.toggle("error", isError);
    if (isError) state.error = text;
  }

  // multipart upload with progress (one file, or several photos of one printed sheet); resolves with {status, json}
  function upload(files) {
    return new Promise((resolve, reject) => {
      const xhr = new XMLHttpRequest();
      const form = new FormData();
      files.forEach((file, i) => form.append("file", file, file.name || `photo-${i + 1}.jpg`));
      xhr.open("POST", "/v1/decode");
      xhr.responseType = "json";
      xhr.upload.onprogress = (e) => {
        if (e.lengthComputable) { $("progress").value = (100 * e.loaded) / e.total; status(`Uploading ${Math.round((100 * e.loaded) / e.total)}%`); }
      };
      xhr.upload.onload = () => { $("progress").removeAttribute("value"); status("Decoding: finding the sheet, restoring the scene…"); };
      xhr.onload = () => resolve({ status: xhr.status, json: xhr.response, retry: xhr.getResponseHeader("Retry-After") });
      xhr.onerror = () => reject(new Error("the server could not be reached"));
      xhr.send(form);
    });
  }

  function requestDraw() {
    if (!dirty) { dirty = true; requestAnimationFrame(drawNow); }
  }

  function drawNow() {
    dirty = false;
    if (state.mode === "webgl2") {
      const canvas = $("view"), px = moving ? state.movingSize : FULL;
      if (canvas.width !== px) { canvas.width = px; canvas.height = px; }
      renderer.draw(state.azimuth, state.elevation, state.distance);
      state.frames++;
    } else if (state.mode === "frames") {
      fetchFrame();
    }
    if (state.firstViewMs === null) state.firstViewMs = Math.round(performance.now() - started);
    if (state.mode === "webgl2" && !state.movingChosen) {  // after the first view is on screen, not before it
      state.movingChosen = true;
      setTimeout(chooseMovingSize, 50);
    }
  }

  // fallback: one server frame in flight at a time, always for the latest pose
  let frameBusy = false, frameAgain = false;
  function fetchFrame() {
    if (frameBusy) { frameAgain = true; return; }
    frameBusy = true;
    const img = $("frame");
    const q = new URLSearchParams({ azimuth: state.azimuth.toFixed(2), elevation: state.elevation.toFixed(2),
                                    distance: state.distance.toFixed(4), size: "380" });
    img.onload = img.onerror = () => { frameBusy = false; state.frames++; if (frameAgain) { frameAgain = false; fetchFrame(); } };
    img.src = `/v1/scenes/${state.sceneId}/render?${q}`;
  }

  function showScene(header, grid) {
    state.header = header;
    state.radius = state.distance = header.orbit.radius;
    state.elevation = header.orbit.elevation_deg;
    state.azimuth = 0;
    const canvas = $("view");
    renderer = grid ? S3DGL.create(canvas, grid) : null;
    state.mode = renderer ? "webgl2" : "frames";
    state.movingChosen = false;
    canvas.hidden = state.mode !== "webgl2";
    $("frame").hidden = state.mode !== "frames";
    $("hint").hidden = false;
    requestDraw();
    state.ready = true;
  }

  // what the photo check found wrong with the photo (glare, tilt, blur), or the general advice
  function retakeAdvice(retake) {
    return retake && retake.length ? retake.join("; ") : "retake the photo square on, in focus, in even light";
  }

  function showReport(body) {
    const q = body.report.quality_estimate || {};
    const el = $("quality");
    el.hidden = false;
    if (q.restore_psnr_expected_db != null) {
      el.textContent = `Expected quality: about ${q.restore_psnr_expected_db.toFixed(1)} dB` +
        (q.restore_psnr_expected_db < 22 ? ` (poor: ${retakeAdvice(body.report.retake)})` : "");
      el.classList.toggle("poor", q.restore_psnr_expected_db < 22);
    } else {
      el.textContent = "Expected quality: no estimate for this kind of input.";
    }
    const ch = body.report.channel || {};   // the pilots' channel (print codecs only): nearest preset and advice
    if (ch.advice) {
      const line = ch.advice.replace(/`/g, "");
      el.textContent += ` ${line.charAt(0).toUpperCase()}${line.slice(1)}.`;
    }
    const l = $("links");
    l.hidden = false;
    l.innerHTML = "";
    for (const [text, href] of [["scene.s3d", body.scene], ["mesh.glb", body.mesh], ["view 0", body.views[0]]]) {
      const a = document.createElement("a");
      a.href = href; a.textContent = text; a.download = "";
      l.appendChild(a);
    }
  }

  // a snapshot PNG with its metadata, decoded in this browser (local.js): nothing is uploaded
  async function decodeHere(file, meta) {
    status("Decoding in this browser…");
    const got = await S3DLocal.decode(file, meta, (text) => status(text));
    state.sceneId = null;
    state.source = "browser";
    showScene(got.header, got);
    const q = $("quality");
    q.hidden = false;
    q.textContent = "Expected quality: no estimate for a snapshot file (it has no markers).";
    $("links").hidden = true;
    const t = got.timings_ms;
    status(`Decoded in this browser in ${t.load + t.restore + t.bake} ms (models ${t.load}, restore ${t.restore}, ` +
           `bake ${t.bake}); nothing was uploaded.`);
    state.local = got;
  }

  // one file, or several photos of one printed sheet (the server combines them, each weighted by its pilots)
  async function decode(files) {
    state.ready = false; state.error = null; state.firstViewMs = null; state.local = null;
    started = performance.now();
    $("progress").hidden = false; $("progress").value = 0;
    try {
      const here = files.length === 1 && hasWebGL2() ? await S3DLocal.readable(files[0]).catch(() => null) : null;
      if (here) { await decodeHere(files[0], here.meta); return; }
      const res = await upload(files);
      if (res.status !== 200) {
        const why = (res.json && res.json.error) || `the server answered ${res.status}`;
        throw new Error(res.status === 503 ? `${why} (try again in ${res.retry || "a few"} s)` : why);
      }
      const body = res.json;
      state.sceneId = body.scene_id;
      state.source = "server";
      status("Loading the scene…");
      const grid = S3DGrid.parse(await (await fetch(body.grid)).arrayBuffer());
      showScene(grid.header, hasWebGL2() ? grid : null);
      showReport(body);
      const t = body.report.timings_ms;
      status(`Decoded in ${Math.round(t.scan + t.restore + t.bake)} ms (${body.report.source}); ` +
             (state.mode === "webgl2" ? "rendered here with WebGL2." : "frames from the server (no WebGL2)."));
    } catch (e) {
      status(`Could not decode ${files.length > 1 ? "these photos" : "this photo"}: ${e.message}`, true);
    } finally {
      $("progress").hidden = true;
    }
  }

  // asked once: every getContext on a fresh canvas makes a WebGL context, and browsers keep only a few
  let webgl2 = null;
  function hasWebGL2() {
    if (webgl2 === null) webgl2 = !!document.createElement("canvas").getContext("webgl2");
    return webgl2;
  }

  $("photo").addEventListener("change", (e) => { if (e.target.files.length) decode(Array.from(e.target.files)); });
  // drop a photo or a snapshot file anywhere on the page
  document.addEventListener("dragover", (e) => e.preventDefault());
  document.addEventListener("drop", (e) => {
    e.preventDefault();
    if (e.dataTransfer.files.length) decode(Array.from(e.dataTransfer.files));
  });

  // drag to orbit, pinch or wheel to zoom
  const stage = $("stage"), pointers = new Map();
  let pinch0 = null;
  stage.addEventListener("pointerdown", (e) => { pointers.set(e.pointerId, [e.clientX, e.clientY]); stage.setPointerCapture(e.pointerId); });
  stage.addEventListener("pointermove", (e) => {
    if (!pointers.has(e.pointerId) || !state.ready) return;
    const [x0, y0] = pointers.get(e.pointerId);
    pointers.set(e.pointerId, [e.clientX, e.clientY]);
    if (pointers.size === 1) {
      state.azimuth -= (e.clientX - x0) * 0.5;
      state.elevation = Math.max(-85, Math.min(85, state.elevation + (e.clientY - y0) * 0.5));
    } else if (pointers.size === 2) {
      const [a, b] = [...pointers.values()];
      const d = Math.hypot(a[0] - b[0], a[1] - b[1]);
      if (pinch0) zoom(pinch0 / d);
      pinch0 = d;
    }
    interacting();
    requestDraw();
  });
  const release = (e) => { pointers.delete(e.pointerId); pinch0 = null; };
  stage.addEventListener("pointerup", release);
  stage.addEventListener("pointercancel", release);
  stage.addEventListener("wheel", (e) => { e.preventDefault(); if (state.ready) { zoom(Math.exp(e.deltaY * 0.001)); interacting(); requestDraw(); } },
                         { passive: false });
  function zoom(f) { state.distance = Math.max(0.3 * state.radius, Math.min(4 * state.radius, state.distance * f)); }

  // frames per second of the client renderer at size x size over n synchronous frames (each one finished)
  state.measureFps = (n = 30, size = FULL) => {
    if (state.mode !== "webgl2") return null;
    const gl = renderer.gl, px = new Uint8Array(4), canvas = $("view");
    canvas.width = canvas.height = size;
    const t0 = performance.now();
    for (let i = 0; i < n; i++) {
      renderer.draw(state.azimuth + i * 3, state.elevation, state.distance);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);  // waits for the frame
    }
    const fps = (1000 * n) / (performance.now() - t0);
    canvas.width = canvas.height = FULL;
    renderer.draw(state.azimuth, state.elevation, state.distance);
    return fps;
  };
  // the moving size from this device's own frame rate at FULL (3 finished frames): the square that
  // keeps TARGET_FPS if time goes with the pixel count, 10% to spare, between MOVING_MIN and FULL
  function chooseMovingSize() {
    if (state.mode !== "webgl2") return null;
    state.measureFps(1, FULL);  // a first frame may still compile the shader
    const fps = state.measureFps(3, FULL);
    const px = Math.round(FULL * Math.sqrt(Math.min(1, fps / TARGET_FPS)) * (fps >= TARGET_FPS ? 1 : 0.9));
    state.movingSize = Math.max(MOVING_MIN, Math.min(FULL, px));
    return state.movingSize;
  }
  state.chooseMovingSize = chooseMovingSize;

  // (H, W) RGBA bytes of a frame drawn at size x size (readPixels: rows bottom-up)
  function pixels(size, azimuth) {
    const gl = renderer.gl, canvas = $("view");
    canvas.width = canvas.height = size;
    renderer.draw(azimuth, state.elevation, state.distance);
    const out = new Uint8Array(4 * size * size);
    gl.readPixels(0, 0, size, size, gl.RGBA, gl.UNSIGNED_BYTE, out);
    return out;
  }

  // PSNR (dB, RGB) of the moving path against the full one: frames drawn at `size`, scaled up bilinearly to
  // FULL as the page's canvas is (CSS smoothing), against frames drawn at FULL; the median over n poses
  state.movingPsnr = (size = state.movingSize, n = 6) => {
    if (state.mode !== "webgl2") return null;
    const out = [], s = size / FULL;
    for (let k = 0; k < n; k++) {
      const az = state.azimuth + k * (360 / n), full = pixels(FULL, az), small = pixels(size, az);
      let se = 0;
      for (let y = 0; y < FULL; y++) {
        const fy = Math.min(Math.max((y + 0.5) * s - 0.5, 0), size - 1), y0 = Math.min(fy | 0, size - 2), wy = fy - y0;
        for (let x = 0; x < FULL; x++) {
          const fx = Math.min(Math.max((x + 0.5) * s - 0.5, 0), size - 1), x0 = Math.min(fx | 0, size - 2), wx = fx - x0;
          const i00 = 4 * (y0 * size + x0), i01 = i00 + 4, i10 = i00 + 4 * size, i11 = i10 + 4, j = 4 * (y * FULL + x);
          for (let c = 0; c < 3; c++) {
            const v = (1 - wy) * ((1 - wx) * small[i00 + c] + wx * small[i01 + c]) + wy * ((1 - wx) * small[i10 + c] + wx * small[i11 + c]);
            se += (v - full[j + c]) ** 2;
          }
        }
      }
      out.push(10 * Math.log10((255 * 255) / Math.max(se / (3 * FULL * FULL), 1e-10)));
    }
    $("view").width = $("view").height = FULL;
    renderer.draw(state.azimuth, state.elevation, state.distance);
    out.sort((a, b) => a - b);
    return out[out.length >> 1];
  };
  state.pose = (azimuth, elevation, distance) => {
    state.azimuth = azimuth; state.elevation = elevation; state.distance = distance ?? state.radius;
    if (state.mode === "webgl2") {
      $("view").width = $("view").height = FULL;
      renderer.draw(state.azimuth, state.elevation, state.distance);
      state.frames++;
    }
    else fetchFrame();
  };
})();
