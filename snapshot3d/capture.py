"""What a fit reads of a capture besides its files: the held-out split, the world box, the up axis, the image
size limit; and the one line that says what was read (`describe`). numpy + OpenCV, no torch."""
from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from . import validate
from .auto_box import box_from_cameras
from .carve import carve, tight_box
from .errors import UserError
from .posed import PosedImages

__all__ = ["CaptureOptions", "parse_box", "parse_up", "cameras_up", "up_rotation", "split", "shrink", "describe",
           "assemble", "builtin_options", "fit_box", "box_from_cameras", "WHITE_BORDER", "choose_background",
           "with_overlap_box"]

DEFAULT_BOX = np.array([[-1.5, -1.5, -1.5], [1.5, 1.5, 1.5]], np.float32)  # NeRF-Synthetic convention
# `fit --background auto`: a capture without masks is "on white" when this share of its frames' border pixels is
# near white (every channel above 0.9): a light box or a paper sweep, which the white background explains
WHITE_BORDER = 0.5


@dataclass(frozen=True)
class CaptureOptions:
    """How a capture is read (fit's --holdout, --box, --up, --max-size); None: the layout's default."""

    holdout: int | None = None
    """every N-th frame (0, N, 2N, ...) is held out for field_psnr; 0: none (the training frames are scored);
    None: the layout's own split (Blender: its test split; nerfstudio, COLMAP: every 8th)"""
    box: tuple | str | None = None
    """(x0, y0, z0, x1, y1, z1) world box, in the world after the up rotation; None: from masks or cameras;
    "auto": without masks, the cube that most views hold in their frame (`auto_box.overlap_box`), else as None"""
    up: object = None
    """"auto" (square to the cameras' level x axes, `cameras_up`), an (x, y, z) vector, or None: the layout's default
    (Blender, builtin: as given; nerfstudio, COLMAP: auto). The world is rotated so that it becomes +z."""
    max_size: int | None = None
    """longest image side in pixels after --downscale (images are shrunk to it); None: no limit"""


def _floats(text: str, n: int, flag: str) -> tuple:
    try:
        vals = tuple(float(v) for v in str(text).replace(" ", "").split(","))
    except ValueError:
        vals = ()
    if len(vals) != n or not all(np.isfinite(vals)):
        raise UserError(f"{flag} takes {n} numbers separated by commas, not {validate.show(text)}")
    return vals


def parse_box(text: str | None) -> tuple | str | None:
    """`--box x0,y0,z0,x1,y1,z1` -> six floats (checked as a scene box); `--box auto` -> "auto"; or None."""
    if text is None or text == "auto":
        return text
    return tuple(validate.check_box(_floats(text, 6, "--box"), "--box").reshape(-1).tolist())


def parse_up(text: str | None):
    """`--up auto` or `--up x,y,z` -> "auto", a unit (x, y, z) tuple, or None."""
    if text is None or text == "auto":
        return text
    v = np.array(_floats(text, 3, "--up"))
    if np.linalg.norm(v) < 1e-9:
        raise UserError("--up must not be the zero vector")
    return tuple((v / np.linalg.norm(v)).tolist())


def check_holdout(n, field: str = "--holdout") -> int:
    """--holdout N checked: 0 (none held out) or N >= 2."""
    n = validate.integer(n, field, 0, 1 << 20)
    if n == 1:
        raise UserError(f"{field} 1 would hold out every frame: give 0 (none) or N >= 2")
    return n


UPRIGHT_SPREAD = 0.15   # rms spread of the cameras' x axes off their main direction that fixes up by the x axes alone


def cameras_up(c2w: np.ndarray) -> tuple[np.ndarray, str]:
    """The world's up from cameras held upright (c2w (N, 4, 4) OpenGL) -> (unit (3,), how). Upright cameras keep
    their x axes (c2w[:, :3, 0]) level, so up is the direction across them (the least singular vector), signed by
    the mean of their up vectors (c2w[:, :3, 1]), as COLMAP's upright alignment and nerfstudio's "vertical" do.
    The mean up alone leans toward the object when the views look down over less than a full turn, or rise as they
    go round. When the x axes hardly spread (rms under UPRIGHT_SPREAD off their main direction: a capture from one
    side), they fix up about one axis only: the mean up, made square to their main direction."""
    x = c2w[:, :3, 0].astype(np.float64)
    x = x / np.linalg.norm(x, axis=1, keepdims=True)
    mean_up = c2w[:, :3, 1].astype(np.float64).mean(0)
    if np.linalg.norm(mean_up) < 1e-3:
        raise UserError("--up auto: the cameras' up vectors cancel out (no common up); give --up x,y,z")
    _, s, vt = np.linalg.svd(x)   # vt (3, 3): two cameras' x axes leave the third direction, their cross product
    if len(s) > 1 and s[1] / np.sqrt(len(x)) >= UPRIGHT_SPREAD:
        u, how = vt[2], "auto: square to the cameras' level x axes"
    else:
        u, how = mean_up - vt[0] * float(vt[0] @ mean_up), "auto: the cameras' mean up, square to their x axes"
    if np.linalg.norm(u) < 1e-3:
        raise UserError("--up auto: the cameras' up vectors lie along their x axes (no common up); give --up x,y,z")
    u = u / np.linalg.norm(u)
    return (u if u @ mean_up > 0 else -u), how


def up_rotation(c2w: np.ndarray, up) -> tuple[np.ndarray, np.ndarray, str]:
    """(R (3, 3), up (3,), how): the smallest rotation taking the world axis `up` ("auto": `cameras_up`; or an
    (x, y, z) vector) to +z, and where that axis came from."""
    m, how = cameras_up(c2w) if isinstance(up, str) else (np.asarray(up, np.float64), "--up")
    u = m / np.linalg.norm(m)
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(u, z), float(u @ z)
    s = np.linalg.norm(v)
    if s < 1e-12:
        return (np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])), u, how
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx * ((1 - c) / s**2), u, how


def split(n: int, holdout: int) -> tuple[np.ndarray, np.ndarray]:
    """(train, test) indices: every `holdout`-th frame from 0 held out; holdout 0: test = train = all."""
    if holdout == 0:
        return np.arange(n), np.arange(n)
    test = np.arange(0, n, holdout)
    train = np.setdiff1d(np.arange(n), test)
    if len(train) < 2:
        raise UserError(f"--holdout {holdout} leaves {len(train)} of {n} frames to train on (2 or more needed)")
    return train, test


def shrink(rgb: np.ndarray, alpha, downscale: int, max_size: int | None, where: str):
    """Divide the size by `downscale`, then shrink (area) so that the longer side is at most `max_size`.
    rgb (H, W, 3), alpha (H, W) or None -> (rgb, alpha, sx, sy): the new over the old width and height, by
    which fx and cx (sx), fy and cy (sy) scale."""
    h, w = rgb.shape[:2]
    nw, nh = w // downscale, h // downscale
    if min(nw, nh) < 1:
        raise UserError(f"{where}: --downscale {downscale} leaves nothing of a {w}x{h} image")
    if max_size and max(nw, nh) > max_size:
        f = max_size / max(nw, nh)
        nw, nh = max(1, round(nw * f)), max(1, round(nh * f))
    if (nw, nh) == (w, h):
        return rgb, alpha, 1.0, 1.0
    rgb = cv2.resize(np.ascontiguousarray(rgb), (nw, nh), interpolation=cv2.INTER_AREA)
    alpha = None if alpha is None else cv2.resize(np.ascontiguousarray(alpha), (nw, nh), interpolation=cv2.INTER_AREA)
    return rgb, alpha, nw / w, nh / h


def _vec(v) -> str:
    """Three significant digits, to 1e-4 (a box's or an axis's rounding noise reads 0)."""
    return "(" + ", ".join(f"{round(float(x), 4) + 0.0:.3g}" for x in v) + ")"


def describe(info: dict) -> str:
    """One line from a loader's `info["capture"]`: frames read and skipped (why), the split, the image size,
    the box and the up axis."""
    c = info
    skipped = sum(c["skipped"].values())
    why = ", ".join(f"{n} {reason}" for reason, n in c["skipped"].items() if n)
    parts = [f"read {c['frames']} frames" + (f", skipped {skipped} ({why})" if skipped else "")]
    if c["holdout"] == 0:
        parts.append(f"{c['train']} train, none held out: field_psnr is scored on the training frames")
    else:
        parts.append(f"{c['train']} train / {c['test']} held out ({c['split']})")
    parts.append(f"images {c['size'][0]}x{c['size'][1]}")
    parts.append(f"box {_vec(c['box'][0])}..{_vec(c['box'][1])} ({c['box_from']})")
    parts.append(f"up {_vec(c['up'])} ({c['up_from']})")
    return f"{c['name']}: " + "; ".join(parts)


def fit_box(images_alpha, c2w, intrinsics, start_box=DEFAULT_BOX, min_views: int = 2) -> np.ndarray:
    """A tight box from coverage masks (visual hull of the voxels at least `min_views` views hold in their
    frame), or `start_box` when there are no masks."""
    if images_alpha is None:
        return start_box.astype(np.float32)
    occ = carve(images_alpha, c2w, intrinsics, start_box, 64, min_views=min_views)
    return tight_box(occ, start_box)


def assemble(frames: list, opts: CaptureOptions, *, where: str, name: str, layout: str, default_up, default_split,
              skipped: dict, box_start) -> PosedImages:
    """Frames (rgb (H, W, 3), alpha (H, W) or None, c2w (4, 4) OpenGL, (fx, fy, cx, cy)) -> PosedImages: the
    world turned so that the up axis is +z, the held-out split, the box (`opts.box`; else carved from the masks
    inside `box_start(c2w, 2)`, or inside DEFAULT_BOX when box_start is None; else `box_start(c2w)`), and
    `info["capture"]`.
    default_split: N (every N-th held out) or (train, test, how)."""
    why = ", ".join(f"{n} {r}" for r, n in skipped.items() if n) or "none skipped"
    if len(frames) < 2:
        raise UserError(f"{where}: fewer than 2 images found ({why})")
    sizes = sorted({f[0].shape[1::-1] for f in frames})
    if len(sizes) > 1:
        raise UserError(f"{where}: images differ in size ({', '.join(f'{w}x{h}' for w, h in sizes[:3])}); resize "
                        "them to one size first")
    c2w = np.stack([f[2] for f in frames]).astype(np.float64)
    intr = np.asarray([f[3] for f in frames], np.float32)
    alphas = [f[1] for f in frames]
    alpha = None if any(a is None for a in alphas) else np.stack(alphas).astype(np.float32)
    up = opts.up if opts.up is not None else default_up
    up_vec, up_from = (0.0, 0.0, 1.0), "as given"
    if up is not None:
        rot, up_vec, up_how = up_rotation(c2w, up)
        c2w[:, :3, :] = np.einsum("ij,njk->nik", rot, c2w[:, :3, :])
        up_from = up_how + ", turned to +z"
    c2w = c2w.astype(np.float32)
    n = len(frames)
    holdout = opts.holdout if opts.holdout is not None else default_split if isinstance(default_split, int) else None
    if holdout is not None:
        train, test = split(n, holdout)
        how = f"every {holdout}-th frame" if holdout else "none held out"
    else:
        train, test, how = default_split
    if opts.box is not None and opts.box != "auto":
        box, box_from = validate.check_box(opts.box, "--box"), "--box"
    elif opts.box == "auto" and alpha is None and box_start is not None:
        from .auto_box import OVERLAP_SHARE, overlap_box
        box = overlap_box(c2w, intr, frames[0][0].shape[1], frames[0][0].shape[0])
        box_from = f"auto: the cube {OVERLAP_SHARE:.0%} of the views hold, round the cameras' look-at point"
    elif box_start is None:   # Blender: carved inside the NeRF-Synthetic box
        box = fit_box(alpha, c2w, intr)
        box_from = "carved from the masks" if alpha is not None else "the NeRF-Synthetic default"
    elif alpha is not None:
        # carved inside a cube twice the cameras' own, then again inside what is left. An object is in the frame
        # of most views of its capture; what half the views do not hold is the few views' long visual-hull spikes
        views = max(2, (n + 1) // 2)
        box = fit_box(alpha, c2w, intr, fit_box(alpha, c2w, intr, box_start(c2w, 2.0), views), views)
        box_from = "carved from the masks"
    else:
        box, box_from = box_start(c2w), "from the cameras"
    box = validate.check_box(box, f"{where}: the scene box found")
    info = {"name": name, "frames": n, "skipped": skipped, "holdout": holdout, "train": len(train),
            "test": 0 if holdout == 0 else len(test), "split": how, "size": list(frames[0][0].shape[1::-1]),
            "box": box.tolist(), "box_from": box_from, "up": [float(x) for x in up_vec], "up_from": up_from}
    return PosedImages(images=np.stack([f[0] for f in frames]).astype(np.float32), alpha=alpha, c2w=c2w,
                       intrinsics=intr, box=box, train=np.asarray(train), test=np.asarray(test), name=name,
                       skipped=int(sum(skipped.values())), info={"layout": layout, "capture": info})


def choose_background(posed: PosedImages, border: float = 0.04) -> tuple[str, str]:
    """`fit --background auto` -> ("white" or "outer", why): white when the capture has masks (the object is
    composited on white) or its frames' borders (`border` of each side) are mostly near white; else outer (a room
    around the object, which the planes must not explain)."""
    if posed.alpha is not None:
        return "white", "auto: the capture has masks"
    n, h, w, _ = posed.images.shape
    bh, bw = max(1, round(h * border)), max(1, round(w * border))
    edge = np.concatenate([posed.images[:, :bh].reshape(-1, 3), posed.images[:, -bh:].reshape(-1, 3),
                           posed.images[:, :, :bw].reshape(-1, 3), posed.images[:, :, -bw:].reshape(-1, 3)])
    white = float((edge.min(axis=1) > 0.9).mean())
    if white >= WHITE_BORDER:
        return "white", f"auto: no masks, {white:.0%} of the frames' border is white"
    return "outer", f"auto: no masks, and only {white:.0%} of the frames' border is white (a room round the object)"


def with_overlap_box(posed: PosedImages) -> PosedImages:
    """`posed` with the automatic box (`--box auto`) in place of the cameras' own, when that is where its box came
    from (a --box given, or one carved from masks, is kept)."""
    read = dict(posed.info.get("capture") or {})
    if posed.alpha is not None or read.get("box_from") != "from the cameras":
        return posed
    from .auto_box import OVERLAP_SHARE, overlap_box
    box = validate.check_box(overlap_box(posed.c2w, posed.intrinsics, posed.width, posed.height),
                             "the scene box found")
    read.update(box=box.tolist(), box_from=f"auto: the cube {OVERLAP_SHARE:.0%} of the views hold, round the "
                "cameras' look-at point")
    return replace(posed, box=box, info={**posed.info, "capture": read})


def builtin_options(posed: PosedImages, opts: CaptureOptions) -> PosedImages:
    """A builtin scene with --up (its box turned with it), --holdout and --box applied; `info["capture"]`."""
    c2w, box = posed.c2w.astype(np.float64), posed.box
    up_vec, up_from = (0.0, 0.0, 1.0), "as given"
    if opts.up is not None:
        rot, up_vec, up_how = up_rotation(c2w, opts.up)
        c2w[:, :3, :] = np.einsum("ij,njk->nik", rot, c2w[:, :3, :])
        corners = np.stack(np.meshgrid(*box.T, indexing="ij"), -1).reshape(-1, 3) @ rot.T
        box = np.stack([corners.min(0), corners.max(0)])
        up_from = up_how + ", turned to +z"
    train, test, how = posed.train, posed.test, "the builtin test views"
    if opts.holdout is not None:
        train, test = split(len(c2w), opts.holdout)
        how = f"every {opts.holdout}-th frame" if opts.holdout else "none held out"
    box, box_from = (validate.check_box(opts.box, "--box"), "--box") if opts.box not in (None, "auto") else \
        (box.astype(np.float32), "the mesh's bounds")
    info = {"name": posed.name, "frames": len(c2w), "skipped": {}, "holdout": opts.holdout, "train": len(train),
            "test": 0 if opts.holdout == 0 else len(test), "split": how, "size": [posed.width, posed.height],
            "box": box.tolist(), "box_from": box_from, "up": [float(x) for x in up_vec], "up_from": up_from}
    return replace(posed, c2w=c2w.astype(np.float32), box=box, train=np.asarray(train), test=np.asarray(test),
                   info={**posed.info, "capture": info})
