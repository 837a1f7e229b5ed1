"""The print-and-capture simulator (DESIGN section 3): a sheet image -> a phone photo and its truth.

Physical presets (`scanner.presets`) print the sheet (`scanner.printing`), place it in 3D before a
12 MP camera (`scanner.pose`), light it (gradient, soft shadow, glare), image it through a lens with
radial distortion, defocus and motion blur, add Poisson-Gaussian sensor noise and a white-balance
error, apply the camera's tone curve and save a JPEG. Deterministic for a seed."""
from __future__ import annotations

import cv2
import numpy as np

from snapshot3d import formats

from . import layout
from .backgrounds import background_names, load_background
from .camera import undistort
from .pose import Pose, sample_pose
from .presets import Preset, get_preset
from .printing import print_sheet, srgb_to_linear

__all__ = ["simulate", "sheet_scale", "blur_kernel"]

_MAP_STEP = 8  # the remap's coordinate maps are computed every this many pixels and interpolated


def sheet_scale(sheet_rgb: np.ndarray) -> float:
    """Sheet pixels per layout unit; ValueError if the image does not have the sheet's aspect ratio."""
    w, h = layout.sheet_size()
    s = sheet_rgb.shape[1] / w
    if abs(sheet_rgb.shape[0] - s * h) > max(2.0, 0.01 * sheet_rgb.shape[0]):
        raise ValueError(f"a {sheet_rgb.shape[1]}x{sheet_rgb.shape[0]} image is not a snapshot3d sheet "
                         f"(aspect {w}:{h})")
    return s


def blur_kernel(defocus_px: float, motion_px: float, angle_rad: float) -> np.ndarray:
    """(k, k) float32 PSF: a defocus disk of radius `defocus_px` convolved with a motion line."""
    r = int(np.ceil(defocus_px + motion_px / 2)) + 1
    k = 2 * r + 1
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float32)
    ss = 4  # supersampled disk edge
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    disk = np.zeros((k, k), np.float32)
    for dy in sub:
        for dx in sub:
            disk += ((xx + dx) ** 2 + (yy + dy) ** 2 <= max(defocus_px, 0.5) ** 2)
    line = np.zeros((k, k), np.float32)
    n = max(2, int(np.ceil(motion_px * 4)))
    for s in np.linspace(-motion_px / 2, motion_px / 2, n):
        x, y = r + s * np.cos(angle_rad), r + s * np.sin(angle_rad)
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - x0, y - y0
        for (yy_, xx_, wgt) in ((y0, x0, (1 - fx) * (1 - fy)), (y0, x0 + 1, fx * (1 - fy)),
                                (y0 + 1, x0, (1 - fx) * fy), (y0 + 1, x0 + 1, fx * fy)):
            line[yy_, xx_] += wgt
    psf = cv2.filter2D(disk, -1, line, borderType=cv2.BORDER_CONSTANT)
    return (psf / psf.sum()).astype(np.float32)


def _low_res_grid(W: int, H: int, step: int):
    xs = np.arange(0, W + step, step, dtype=np.float64)
    ys = np.arange(0, H + step, step, dtype=np.float64)
    return np.meshgrid(xs, ys)


def _lighting(p: Preset, pose: Pose, rng, W: int, H: int, params: dict) -> tuple[np.ndarray, np.ndarray]:
    """Illumination (multiplicative) and glare (additive), both (H, W) float32, built at 1/16 scale."""
    gx, gy = _low_res_grid(W, H, 16)
    u, v = gx / W - 0.5, gy / H * (H / W) - 0.5 * H / W
    grad = float(rng.uniform(*p.gradient))
    ang = rng.uniform(0, 2 * np.pi)
    ramp = u * np.cos(ang) + v * np.sin(ang)
    ramp = (ramp - ramp.min()) / max(np.ptp(ramp), 1e-9)
    light = float(rng.uniform(*p.exposure)) * (1.0 - grad * ramp)
    centre = pose.to_photo(np.array([formats.SNAPSHOT_SIZE / 2] * 2))
    shadow = float(rng.uniform(*p.shadow))
    sang = rng.uniform(0, 2 * np.pi)
    off = rng.uniform(-0.15, 0.15) * W
    soft = rng.uniform(0.01, 0.05) * W
    d = (gx - centre[0]) * np.cos(sang) + (gy - centre[1]) * np.sin(sang) - off
    light = light * (1.0 - shadow / (1.0 + np.exp(-d / soft)))
    glare = float(rng.uniform(*p.glare))
    gc = pose.to_photo(rng.uniform(0, formats.SNAPSHOT_SIZE, size=2))
    gs = rng.uniform(0.02, 0.06) * W
    spot = glare * np.exp(-((gx - gc[0]) ** 2 + (gy - gc[1]) ** 2) / (2 * gs ** 2))
    params.update(gradient=grad, shadow=shadow, shadow_softness_px=float(soft), glare=glare,
                  glare_centre_px=gc.tolist(), glare_sigma_px=float(gs))
    up = lambda a: cv2.resize(a.astype(np.float32), (W, H), interpolation=cv2.INTER_LINEAR)  # noqa: E731
    return up(light), up(spot)


def _warp_print(printed: np.ndarray, dots_per_unit: float, pose: Pose, frame: np.ndarray) -> tuple:
    """Render the printed sheet (linear, printer dots) into `frame` (H, W, 3) in place. Returns the ROI."""
    H_img, W_img = frame.shape[:2]
    x0, y0, x1, y1 = formats.SHEET_BOX
    q = pose.to_photo(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64))
    rx0, ry0 = np.maximum(np.floor(q.min(0)).astype(int) - 4, 0)
    rx1, ry1 = np.minimum(np.ceil(q.max(0)).astype(int) + 5, [W_img, H_img])
    # anti-aliasing: shrink the print by area averaging where it is minified (dots per photo pixel > 1)
    side_px = np.linalg.norm(q[1] - q[0]) / (x1 - x0)  # photo pixels per layout unit, roughly
    shrink = max(1, int(dots_per_unit / side_px))
    if shrink > 1:
        printed = cv2.resize(printed, (printed.shape[1] // shrink, printed.shape[0] // shrink), interpolation=cv2.INTER_AREA)
        dots_per_unit = printed.shape[1] / (x1 - x0)
    gx, gy = np.meshgrid(np.arange(rx0, rx1 + _MAP_STEP, _MAP_STEP, dtype=np.float64),
                         np.arange(ry0, ry1 + _MAP_STEP, _MAP_STEP, dtype=np.float64))
    ideal = undistort(np.stack([gx, gy], -1), pose.camera)
    Hinv = np.linalg.inv(pose.H)
    lay = ideal @ Hinv[:, :2].T + Hinv[:, 2]
    lay = lay[..., :2] / lay[..., 2:3]
    src = (lay - np.array([x0, y0])) * dots_per_unit - 0.5
    roi_w, roi_h = rx1 - rx0, ry1 - ry0
    # grid point i lies at ROI pixel i * _MAP_STEP: resample the maps with that exact affine
    A = np.array([[1.0 / _MAP_STEP, 0, 0], [0, 1.0 / _MAP_STEP, 0]], np.float32)
    mx = cv2.warpAffine(src[..., 0].astype(np.float32), A, (roi_w, roi_h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                        borderMode=cv2.BORDER_REPLICATE)
    my = cv2.warpAffine(src[..., 1].astype(np.float32), A, (roi_w, roi_h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                        borderMode=cv2.BORDER_REPLICATE)
    roi = frame[ry0:ry1, rx0:rx1]
    cv2.remap(printed, mx, my, cv2.INTER_LINEAR, dst=roi, borderMode=cv2.BORDER_TRANSPARENT)
    return (rx0, ry0, rx1, ry1)


def simulate(sheet_rgb: np.ndarray, severity, seed: int, print_seed: int | None = None) -> tuple[bytes, str, dict]:
    """Photograph a sheet. sheet_rgb: (H, W, 3) uint8 RGB sheet image (`scanner.sheet`); severity: a preset
    name (`scanner.presets.SEVERITIES`) or a `Preset`. `print_seed`: the print comes from its own seed (its
    halftone screens and paper), so that several photos (`seed`s) show one print, as a user's do; None: the
    print is drawn from `seed` too (one print per photo).

    Returns (encoded photo bytes, ".png" or ".jpg", truth) where truth holds `corners` (4, 2) of the
    snapshot in photo pixels, clockwise from the snapshot's top-left, and the preset and sampled values."""
    p = get_preset(severity)
    scale = sheet_scale(sheet_rgb)
    rng = np.random.default_rng(seed)
    truth = {"severity": p.name, "seed": int(seed), "print_seed": print_seed, "preset": p.as_dict()}
    if not p.physical:
        to_px = layout.layout_to_pixels(scale)
        corners = layout.snapshot_corners() @ to_px[:2, :2].T + to_px[:2, 2]
        bgr = cv2.cvtColor(sheet_rgb, cv2.COLOR_RGB2BGR)
        q = p.jpeg_quality[0]
        ok, buf = cv2.imencode(".png" if q == 0 else ".jpg", bgr, [] if q == 0 else [cv2.IMWRITE_JPEG_QUALITY, q])
        truth.update(corners=corners.tolist(), frame=[sheet_rgb.shape[1], sheet_rgb.shape[0]], jpeg_quality=q)
        return buf.tobytes(), ".png" if q == 0 else ".jpg", truth
    W, H = p.frame
    d = max(1, round(p.print_dots_per_px / scale))
    printed = print_sheet(sheet_rgb, p, d, rng if print_seed is None else np.random.default_rng(print_seed))
    pose = sample_pose(p, rng)
    params: dict = {}
    names = background_names()
    bg_name = names[int(rng.integers(len(names)))]
    bg = srgb_to_linear(load_background(bg_name))
    bh, bw = bg.shape[:2]
    cw, ch = int(bw * rng.uniform(0.5, 1.0)), int(bh * rng.uniform(0.5, 1.0))
    cx0, cy0 = int(rng.integers(0, bw - cw + 1)), int(rng.integers(0, bh - ch + 1))
    albedo = float(rng.uniform(0.25, 0.9))
    frame = cv2.resize(np.ascontiguousarray(bg[cy0:cy0 + ch, cx0:cx0 + cw]) * albedo, (W, H),
                       interpolation=cv2.INTER_LINEAR)
    roi = _warp_print(printed, scale * d, pose, frame)
    light, glare = _lighting(p, pose, rng, W, H, params)
    wb = 1.0 + rng.uniform(-p.white_balance, p.white_balance, size=3)
    frame *= light[..., None]
    frame += glare[..., None]
    # optics: defocus and motion blur, applied around the sheet (the background is already soft)
    defocus, motion = float(rng.uniform(*p.defocus_px)), float(rng.uniform(*p.motion_px))
    mang = float(rng.uniform(0, np.pi))
    psf = blur_kernel(defocus, motion, mang)
    pad = psf.shape[0]
    x0, y0 = max(roi[0] - pad, 0), max(roi[1] - pad, 0)
    x1, y1 = min(roi[2] + pad, W), min(roi[3] + pad, H)
    frame[y0:y1, x0:x1] = cv2.filter2D(frame[y0:y1, x0:x1], -1, psf, borderType=cv2.BORDER_REFLECT)
    # sensor: white-balance error, Poisson-Gaussian noise (heteroscedastic Gaussian approximation)
    frame *= wb.astype(np.float32)
    np.clip(frame, 0.0, 1.0, out=frame)
    a, b = float(rng.uniform(*p.noise_shot)), float(rng.uniform(*p.noise_read))
    noise = np.empty_like(frame)
    cv2.setRNGSeed(int(rng.integers(2**31)))
    cv2.randn(noise, 0.0, 1.0)
    std = cv2.sqrt(frame * a + b * b)
    frame += noise * std
    np.clip(frame, 0.0, 1.0, out=frame)
    # the camera's tone curve (a 1/2.2 gamma), 8 bits, JPEG
    out = cv2.convertScaleAbs(cv2.pow(frame, 1 / 2.2), alpha=255.0)
    q = int(rng.integers(p.jpeg_quality[0], p.jpeg_quality[1] + 1))
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(out, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, q])
    corners = pose.to_photo(layout.snapshot_corners())
    params.update(background=bg_name, background_albedo=albedo, dots_per_sheet_px=d, defocus_px=defocus,
                  motion_px=motion, motion_angle_deg=float(np.rad2deg(mang)), noise_shot=a, noise_read=b,
                  white_balance_gains=wb.tolist(), jpeg_quality=q)
    truth.update(corners=corners.tolist(), frame=[W, H], pose=pose.as_dict(), sampled=params)
    return buf.tobytes(), ".jpg", truth
