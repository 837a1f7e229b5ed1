// The baked grid (format: viewer/gridfile.py) and the orbit camera (as snapshot3d.cameras.view_camera).
"use strict";

const S3DGrid = {
  // ArrayBuffer -> {header, cells: Uint8Array (B*B*B*4, rgba, x fastest, then y, then z)}
  parse(buffer) {
    const magic = new TextDecoder().decode(new Uint8Array(buffer, 0, 8));
    if (magic !== "S3DGRID1") throw new Error("the server sent something that is not a snapshot3d grid");
    const n = new DataView(buffer).getUint32(8, true);
    const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 12, n)));
    const b = header.res;
    const cells = new Uint8Array(buffer, 12 + n);
    if (cells.length !== b * b * b * 4) throw new Error("the grid is truncated");
    return { header, cells };
  },

  // The box's normalised frame (viewer/march.py Frame): centre, scale, half_unit.
  frame(header) {
    const [lo, hi] = header.box;
    const centre = lo.map((v, k) => (v + hi[k]) / 2);
    const half = lo.map((v, k) => (hi[k] - v) / 2);
    const scale = Math.max(...half);
    return { centre, scale, halfUnit: half.map((h) => h / scale) };
  },

  // Camera on the orbit sphere: eye, and the right / up / back axes (OpenGL: looks down -back), world z up.
  camera(header, azimuthDeg, elevationDeg, distance) {
    const az = (azimuthDeg * Math.PI) / 180, el = (elevationDeg * Math.PI) / 180;
    const t = header.orbit.target;
    const eye = [t[0] + distance * Math.cos(el) * Math.cos(az), t[1] + distance * Math.cos(el) * Math.sin(az),
                 t[2] + distance * Math.sin(el)];
    const norm = (v) => { const l = Math.hypot(...v); return v.map((x) => x / l); };
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const back = norm(eye.map((v, k) => v - t[k]));
    let right = cross(header.world_up, back);
    if (Math.hypot(...right) < 1e-8) right = cross([0, 1, 0], back);
    right = norm(right);
    return { eye, right, up: cross(back, right), back };
  },
};
