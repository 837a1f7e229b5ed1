"""`snapshot3d make-capture builtin:NAME -o DIR`: a synthetic capture that looks like a real one, written in the
nerfstudio `transforms.json` layout (docs/capture.md): a built-in mesh on a textured ground plane in a room
wrapped with a photo (`synth_room`), seen from a hand-held walk with OPENCV lens distortion, per-frame exposure
and optional pose noise (`synth_camera`). Ground truth is kept aside in DIR/gt/: the object's masks, its true
box and poses (truth.json), a transforms_masked.json that adds the masks, for the masked fit of the same scene, and
the object alone over white (transforms_white.json), what a fit of the object alone is scored against.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np

from . import validate
from .errors import UserError
from .make_capture_config import SynthCaptureConfig

__all__ = ["check_config", "synth_capture", "write_capture", "make_capture", "make_capture_command"]

CHUNK = 16   # views rasterised together


def check_config(cfg: SynthCaptureConfig) -> SynthCaptureConfig:
    """The config with its values checked (UserError, one line, naming the option)."""
    validate.integer(cfg.views, "--views", 2, 5000)
    validate.number(cfg.arc_deg, "--arc-deg", 10.0, 720.0)
    validate.integer(cfg.size, "--size", 16, 4096)
    validate.number(cfg.fov_deg, "--fov-deg", 10.0, 120.0)
    validate.number(cfg.exposure_jitter, "--exposure-jitter", 0.0, 3.0)
    validate.number(cfg.pose_noise_deg, "--pose-noise-deg", 0.0, 30.0)
    validate.number(cfg.pose_noise_frac, "--pose-noise-frac", 0.0, 0.5)
    validate.numbers(cfg.lens, "--lens (k1 k2 p1 p2)", 4, -1.0, 1.0)
    return cfg


def _mesh_name(spec: str) -> str:
    if not isinstance(spec, str) or not spec.startswith("builtin:"):
        raise UserError(f"make-capture takes builtin:NAME (a built-in mesh), not {validate.show(spec)}")
    return spec.split(":", 1)[1]


def synth_capture(spec: str, cfg: SynthCaptureConfig, keep_pinhole: bool = False) -> dict:
    """Render the capture in memory. Returns a dict of arrays (N frames, H x W = size x 3/4 size):
    images (N, H, W, 3) float32 RGB as written (lens and exposure applied); masks (N, H, W) bool, the object in
    the written images; white (N, H, W, 3) float32 RGB, the object alone over white as the same camera would take
    it (lens and exposure applied; its outline blends with white where the photos blend with the room); with `keep_pinhole`, pinhole (N, H, W, 3) and pinhole_alpha (N, H, W) float32 coverage:
    the same frames before the lens;
    c2w_true, c2w_written (N, 4, 4) float64 OpenGL; intr (4,) (fx, fy, cx, cy); gains (N, 3); box (2, 3) the
    object's true bounds; and `sources` (the photos used)."""
    from .builtin import load_mesh, render_mesh, shared_data_dir
    from .cameras import focal_from_fov
    from .synth_camera import distort_maps, expose, perturb_poses, walk_poses
    from .synth_room import make_room, photo_pool, read_photo, render_room

    cfg = check_config(cfg)
    mesh = load_mesh(_mesh_name(spec))
    rng = np.random.default_rng(cfg.seed)
    w, h = cfg.size, max(8, round(cfg.size * 3 / 4))
    pool = photo_pool(shared_data_dir())
    picks = rng.permutation(len(pool))
    backdrop = pool[picks[0]] if cfg.backdrop == "auto" else cfg.backdrop
    ground = next(pool[i] for i in picks if pool[i] != backdrop) if len(pool) > 1 else pool[0]
    room = make_room(mesh, read_photo(backdrop), read_photo(ground, 512) if cfg.ground else None, rng)
    f = focal_from_fov(np.deg2rad(cfg.fov_deg), w)
    intr = np.array([f, f, w / 2 + rng.uniform(-0.01, 0.01) * w, h / 2 + rng.uniform(-0.01, 0.01) * h])
    lo, hi = mesh.bounds
    centre = 0.5 * (lo + hi)
    radius = float(np.linalg.norm(np.asarray(mesh.vertices) - centre, axis=1).max())
    c2w = walk_poses(cfg.views, centre, radius, f / (h / 2), rng, np.deg2rad(cfg.arc_deg))
    map_x, map_y, (px, py) = distort_maps(w, h, intr, cfg.lens)
    big = intr + np.array([0, 0, px, py])
    n = cfg.views
    gains = np.exp2(cfg.exposure_jitter * rng.standard_normal((n, 1)) + cfg.exposure_jitter / 4 *
                    rng.standard_normal((n, 3))).astype(np.float32)
    out = {"images": np.empty((n, h, w, 3), np.float32), "masks": np.empty((n, h, w), bool),
           "white": np.empty((n, h, w, 3), np.float32)}
    if keep_pinhole:
        out.update(pinhole=np.empty((n, h, w, 3), np.float32), pinhole_alpha=np.empty((n, h, w), np.float32))
    for j in range(0, n, CHUNK):   # the object on white, a few views at a time (memory)
        objs, alphas = render_mesh(mesh, c2w[j:j + CHUNK], np.tile(big, (len(c2w[j:j + CHUNK]), 1)), w + 2 * px,
                                   h + 2 * py)
        for i, obj, alpha in zip(range(j, n), objs, alphas):
            a = alpha[..., None]
            frame = expose(obj - (1 - a) + (1 - a) * render_room(room, c2w[i], big, w + 2 * px, h + 2 * py), gains[i])
            out["images"][i] = cv2.remap(frame, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            out["white"][i] = cv2.remap(expose(obj, gains[i]), map_x, map_y, cv2.INTER_LINEAR,
                                        borderMode=cv2.BORDER_REPLICATE)
            out["masks"][i] = cv2.remap(alpha, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE) >= 0.5
            if keep_pinhole:
                out["pinhole"][i], out["pinhole_alpha"][i] = frame[py:py + h, px:px + w], alpha[py:py + h, px:px + w]
    noisy = perturb_poses(c2w, centre, cfg.pose_noise_deg, cfg.pose_noise_frac, rng)
    return {**out, "c2w_true": c2w, "c2w_written": noisy, "intr": intr, "gains": gains,
            "box": np.stack([lo, hi]), "sources": {"backdrop": backdrop, "ground": ground if cfg.ground else None}}


def _png(path: Path, rgb: np.ndarray) -> None:
    img = np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8)
    if not cv2.imwrite(str(path), img[..., ::-1] if img.ndim == 3 else img):
        raise UserError(f"cannot write {path}")


def write_capture(cap: dict, spec: str, cfg: SynthCaptureConfig, out: Path) -> None:
    """Write `synth_capture`'s result as a nerfstudio capture into the folder `out` (which must exist, empty)."""
    n, h, w = cap["masks"].shape
    (out / "images").mkdir()
    (out / "gt" / "masks").mkdir(parents=True)
    (out / "gt" / "white").mkdir()
    k1, k2, p1, p2 = (float(c) for c in cfg.lens)
    fx, fy, cx, cy = (float(v) for v in cap["intr"])
    head = {"camera_model": "OPENCV", "fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": w, "h": h,
            "k1": k1, "k2": k2, "p1": p1, "p2": p2}
    frames, masked, true_posed, white, truth = [], [], [], [], []
    for i in range(n):
        name = f"frame_{i + 1:05d}.png"
        _png(out / "images" / name, cap["images"][i])
        _png(out / "gt" / "masks" / name, cap["masks"][i].astype(np.float32))
        _png(out / "gt" / "white" / name, cap["white"][i])
        pose = np.round(cap["c2w_written"][i], 8).tolist()
        frames.append({"file_path": f"images/{name}", "transform_matrix": pose})
        masked.append({"file_path": f"../images/{name}", "mask_path": f"masks/{name}", "transform_matrix": pose})
        true_posed.append({**masked[-1], "transform_matrix": np.round(cap["c2w_true"][i], 8).tolist()})
        white.append({**true_posed[-1], "file_path": f"white/{name}"})
        truth.append({"file_path": f"images/{name}", "transform_matrix": np.round(cap["c2w_true"][i], 8).tolist(),
                      "exposure_gain_rgb": [round(float(g), 5) for g in cap["gains"][i]]})
    (out / "transforms.json").write_text(json.dumps({**head, "frames": frames}, indent=1))
    (out / "gt" / "transforms_masked.json").write_text(json.dumps({**head, "frames": masked}, indent=1))
    (out / "gt" / "transforms_true.json").write_text(json.dumps({**head, "frames": true_posed}, indent=1))
    (out / "gt" / "transforms_white.json").write_text(json.dumps({**head, "frames": white}, indent=1))
    info = {"scene": spec, "config": {**asdict(cfg), "lens": list(cfg.lens)}, "box": cap["box"].tolist(),
            "world": "z up; the object stands on the ground plane z = box[0][2] (when there is one)",
            "transforms_true": "gt/transforms_true.json: the masked capture with the true poses (what a fit is scored "
                               "on; transforms*.json carry the poses with --pose-noise-*)",
            "transforms_white": "gt/transforms_white.json: the object alone over white (gt/white/*.png, lens and "
                                "exposure as in the photos) at the true poses, with the masks: the clean object that "
                                "the snapshot should carry",
            "masks": "gt/masks/*.png: 255 where the object covers at least half the pixel, in the written (distorted) "
                     "images", "sources": cap["sources"], "frames": truth}
    (out / "gt" / "truth.json").write_text(json.dumps(info, indent=1))


def make_capture(spec: str, out_dir: str | os.PathLike, cfg: SynthCaptureConfig = SynthCaptureConfig()) -> Path:
    """Render and write a capture to `out_dir` (absent or empty), through a temporary folder beside it renamed
    at the end, so that a failure leaves nothing half-written. Returns the folder."""
    out = Path(out_dir)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UserError(f"{out} already exists and is not an empty folder; give a new one")
    _mesh_name(spec)
    check_config(cfg)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    except OSError as e:
        raise UserError(f"cannot write to {out.parent} ({e.strerror or type(e).__name__})") from None
    try:
        write_capture(synth_capture(spec, cfg), spec, cfg, tmp)
        tmp.chmod(0o755)
        if out.exists():
            out.rmdir()
        tmp.rename(out)
    except OSError as e:
        raise UserError(f"cannot write the capture to {out} ({e.strerror or type(e).__name__})") from None
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out


def make_capture_command(args) -> int:
    from .options import config_from_args

    cfg = config_from_args(SynthCaptureConfig, args)
    out = make_capture(args.scene, args.output, cfg)
    print(f"wrote {cfg.views} frames of {cfg.size}x{max(8, round(cfg.size * 3 / 4))} to {out} (transforms.json; "
          f"ground truth in {out / 'gt'}: masks, the object over white, truth.json, transforms_masked.json, "
          f"transforms_true.json, transforms_white.json)")
    return 0
