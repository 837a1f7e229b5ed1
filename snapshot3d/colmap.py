"""COLMAP's sparse text model (`cameras.txt`, `images.txt`) read into cameras: numpy only, no images.

COLMAP stores world-to-camera poses (quaternion qw qx qy qz, translation) in OpenCV camera axes (x right,
y down, looking down +z); they come out as OpenGL camera-to-world (4, 4) as every loader hands out
(`snapshot3d.cameras`). Principal points are in COLMAP's convention, the project's (pixel centres at +0.5).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import lens, validate
from .errors import UserError

__all__ = ["ColmapCamera", "ColmapImage", "find_model", "read_cameras", "read_images", "quat_to_matrix"]

PARAMS = {"SIMPLE_PINHOLE": ("f", "cx", "cy"), "PINHOLE": ("fx", "fy", "cx", "cy"),
          "SIMPLE_RADIAL": ("f", "cx", "cy", "k1"), "RADIAL": ("f", "cx", "cy", "k1", "k2"),
          "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
          "OPENCV_FISHEYE": ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")}
MAX_LINES = 1 << 22   # a model of some million images is not a capture to fit
OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True)
class ColmapCamera:
    model: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    coeffs: np.ndarray   # OpenCV order (`lens.lens_coeffs`)


@dataclass(frozen=True)
class ColmapImage:
    name: str
    camera_id: int
    c2w: np.ndarray      # (4, 4) float64, OpenGL axes


def find_model(folder: Path) -> Path | None:
    """The folder holding `cameras.txt` and `images.txt`: `folder` itself, `folder/sparse/0` or
    `folder/sparse`; None when there is none. A binary model (cameras.bin) is refused with the command that
    converts it."""
    for d in (folder, folder / "sparse" / "0", folder / "sparse"):
        if (d / "cameras.txt").is_file() and (d / "images.txt").is_file():
            return d
        if (d / "cameras.bin").is_file():
            raise UserError(f"{d}: a binary COLMAP model; convert it to text first: colmap model_converter "
                            f"--input_path {d} --output_path {d} --output_type TXT")
    return None


def _lines(path: Path) -> list[tuple[int, str]]:
    """(line number, text) of the lines that are not comments; blank lines are kept (images.txt has them)."""
    try:
        if path.stat().st_size > 64 * MAX_LINES:
            raise UserError(f"{path}: {path.stat().st_size / 1e6:.0f} MB is too large for a COLMAP model")
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise UserError(f"{path}: cannot read ({type(e).__name__})") from None
    return [(i + 1, ln.strip()) for i, ln in enumerate(text.splitlines()) if not ln.lstrip().startswith("#")]


def read_cameras(path: Path) -> dict[int, ColmapCamera]:
    """cameras.txt: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]` per line -> {id: ColmapCamera}."""
    cams = {}
    for no, line in _lines(path):
        if not line:
            continue
        tok = line.split()
        where = f"{path} line {no}"
        if len(tok) < 4:
            raise UserError(f"{where}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS..., got {len(tok)} fields")
        model = tok[1].upper()
        if model not in PARAMS:
            raise UserError(f"{where}: camera model {tok[1][:40]!r} is not supported (one of {', '.join(PARAMS)})")
        names = PARAMS[model]
        if len(tok) != 4 + len(names):
            raise UserError(f"{where}: a {model} camera has {len(names)} parameters ({' '.join(names)}), got "
                            f"{len(tok) - 4}")
        try:
            cid, w, h = int(tok[0]), int(tok[2]), int(tok[3])
            vals = dict(zip(names, (float(t) for t in tok[4:])))
        except ValueError:
            raise UserError(f"{where}: expected numbers, got {validate.show(line)}") from None
        validate.check_image_size(w, h, where)
        if not all(np.isfinite(v) for v in vals.values()):
            raise UserError(f"{where}: parameters must be finite numbers")
        fx, fy = vals.get("fx", vals.get("f")), vals.get("fy", vals.get("f"))
        if min(fx, fy) <= 0:
            raise UserError(f"{where}: the focal length must be positive")
        cams[cid] = ColmapCamera(model, w, h, fx, fy, vals["cx"], vals["cy"], lens.lens_coeffs(model, vals))
    if not cams:
        raise UserError(f"{path}: no cameras")
    return cams


def quat_to_matrix(qw: float, qx: float, qy: float, qz: float) -> np.ndarray:
    """(3, 3) rotation of a quaternion (normalised first), Hamilton convention as COLMAP."""
    q = np.array([qw, qx, qy, qz], np.float64)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def read_images(path: Path, cameras: dict[int, ColmapCamera]) -> list[ColmapImage]:
    """images.txt: two lines per image, `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME` and its 2D points
    (`X Y POINT3D_ID` triples, possibly blank) -> ColmapImages, sorted by name."""
    lines = _lines(path)
    while lines and not lines[-1][1]:
        lines.pop()
    out = []
    for k in range(0, len(lines), 2):
        no, line = lines[k]
        tok = line.split()
        where = f"{path} line {no}"
        if len(tok) < 10:
            raise UserError(f"{where}: expected 10 fields (IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME), got "
                            f"{len(tok)}")
        try:
            q, t, cid = [float(v) for v in tok[1:5]], [float(v) for v in tok[5:8]], int(tok[8])
        except ValueError:
            raise UserError(f"{where}: expected numbers in IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID, got "
                            f"{validate.show(' '.join(tok[:9]))}") from None
        if not np.isfinite(q + t).all() or np.linalg.norm(q) < 1e-9:
            raise UserError(f"{where}: the pose must be finite numbers with a non-zero quaternion")
        if cid not in cameras:
            raise UserError(f"{where}: CAMERA_ID {cid} is not in cameras.txt")
        if k + 1 < len(lines) and len(lines[k + 1][1].split()) % 3:
            raise UserError(f"{path} line {lines[k + 1][0]}: the 2D points must be X Y POINT3D_ID triples, got "
                            f"{len(lines[k + 1][1].split())} numbers (is a pose line or a points line missing?)")
        r = quat_to_matrix(*q)
        c2w = np.eye(4)
        c2w[:3, :3], c2w[:3, 3] = r.T, -r.T @ np.asarray(t)
        out.append(ColmapImage(" ".join(tok[9:]), cid, c2w @ OPENCV_TO_OPENGL))
    if not out:
        raise UserError(f"{path}: no images")
    return sorted(out, key=lambda im: im.name)
