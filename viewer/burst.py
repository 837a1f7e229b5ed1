"""Several photos of one printed sheet -> one capture (numpy, torch-free).

A print's own noise (its halftone, its paper) is the same in every photo of it; the photo's (blur, light,
glare, sensor, JPEG) is not. The rectified captures of one sheet are therefore averaged pixel by pixel with the
weights of the best linear unbiased estimate under the noise the print codec's pilots measure on each: every
photo's 256 pilot readings, divided by its gain, leave a residual; the residuals' covariance across the photos
(the common part is the print's) gives the weights a = S^-1 1 / (1' S^-1 1), clipped at 0. Where the photos'
noises are independent that is the maximal-ratio weight g^2 / n; where the print's noise dominates it leans on
the photo with the least noise of its own, as choosing the best photo would, and a blurred or glared photo
counts for little instead of spoiling the rest. Measured in docs/print-codec.md ("Several photos of one print")
with `snapshot3d bench burst`.

Layouts: captures (K, 380, 380, 3) uint8 RGB, rectified by the scanner; the combined capture the same, (380, 380, 3)."""
from __future__ import annotations

import numpy as np

from snapshot3d.errors import UserError

__all__ = ["pilot_residuals", "blue_weights", "pilot_weights", "combine_captures", "same_sheet", "detail_match",
           "MAX_PHOTOS", "MIN_MATCH"]

MAX_PHOTOS = 8
"""photos `decode` combines at most (each costs a scan and a reading of its pilots)"""
MIN_MATCH = 0.3
"""`detail_match` below which two captures are not of one print: photos of one print measured 0.54-0.96 (`moderate`
and `severe`, coffee and chelsea), of two prints of one scene in different hosts 0.01-0.13 (docs/print-codec.md)"""
_RIDGE = 0.01
"""added to the residuals' covariance, times its mean variance: 256 pilots estimate it, not know it"""


def pilot_residuals(capture: np.ndarray, res: int, channels: int, codec: str) -> tuple[float, np.ndarray]:
    """A capture's pilots read by the print codec's numpy receiver (`codecs.print_read`, the restore graph's
    reference): (gain, residuals (P,) of the pilots' readings divided by the gain, less their values). ValueError
    for a layout the codec refuses; the gain may be <= 0 (no signal), which the caller refuses."""
    from snapshot3d.codecs.print_carriers import PILOTS, print_layout
    from snapshot3d.codecs.print_read import read_carriers

    lay = print_layout(res, channels, codec)
    pilots = read_carriers(capture, lay)[0][:PILOTS] * lay.pilot_signs
    gain = float(np.mean(pilots)) / lay.pilot_amp
    return gain, (pilots / gain - lay.pilot_amp if gain > 0 else np.full(PILOTS, np.inf))


def blue_weights(gains, residuals) -> np.ndarray:
    """Pixel weights (K,) summing to 1 for captures with pilot gains (K,) and residuals (K, P) (`pilot_residuals`):
    the reading of the weighted capture is then the best linear unbiased combination of the photos' readings. A
    photo whose pilots read no signal (gain <= 0, residuals not finite) gets weight 0; ValueError when none reads."""
    g = np.asarray(gains, np.float64)
    d = np.asarray(residuals, np.float64)
    if d.ndim != 2 or g.shape != (d.shape[0],) or not len(g):
        raise ValueError(f"gains {g.shape} and residuals {d.shape} must be (K,) and (K, P), K >= 1")
    ok = np.isfinite(g) & (g > 0) & np.all(np.isfinite(d), axis=1)
    if not ok.any():
        raise ValueError("no photo's pilots read a signal")
    d, gk = d[ok], g[ok]
    cov = d @ d.T / d.shape[1]
    cov += _RIDGE * max(float(np.mean(np.diag(cov))), 1e-30) * np.eye(len(gk))
    a = np.clip(np.linalg.solve(cov, np.ones(len(gk))), 0.0, None)
    if not a.sum() > 0:
        a = np.ones(len(gk))
    c = np.zeros(len(g))
    c[ok] = a / gk   # a weighs the readings divided by each gain; the pixels carry the gain
    return c / c.sum()


def pilot_weights(gains, noises) -> np.ndarray:
    """(K,) pixel weights summing to 1 from each photo's pilot gain and noise power per carrier (both (K,), > 0):
    proportional to g / n, the maximal-ratio weights were the photos' noises independent (the bench's
    `independent` row; `blue_weights` is what `decode` uses)."""
    g = np.asarray(gains, np.float64)
    n = np.asarray(noises, np.float64)
    if g.shape != n.shape or g.ndim != 1 or not len(g):
        raise ValueError(f"gains {g.shape} and noises {n.shape} must be the same (K,) shape, K >= 1")
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(n)) and np.all(g > 0) and np.all(n > 0)):
        raise ValueError("pilot gains and noises must be finite and positive")
    w = g / n
    return w / w.sum()


def combine_captures(captures, weights) -> np.ndarray:
    """The weighted mean of rectified captures (K, 380, 380, 3) uint8 with weights (K,) summing to 1, rounded
    to (380, 380, 3) uint8 (what the restore graph reads)."""
    x = np.asarray(captures)
    w = np.asarray(weights, np.float64)
    if x.ndim != 4 or x.dtype != np.uint8 or x.shape[0] != len(w):
        raise ValueError(f"captures must be (K, H, W, 3) uint8 with one weight each, got {x.shape} {x.dtype} and "
                         f"{len(w)} weights")
    mean = np.tensordot(w, x.astype(np.float64), axes=1)
    return np.clip(np.rint(mean), 0, 255).astype(np.uint8)


def detail_match(a: np.ndarray, b: np.ndarray) -> float:
    """The correlation of two rectified captures (380, 380, 3) uint8 RGB in their host's detail (luma, a
    difference of Gaussians of 1.5 and 6 px, which light, shadow and white balance leave alone)."""
    import cv2

    def detail(x):
        g = cv2.cvtColor(x, cv2.COLOR_RGB2GRAY).astype(np.float32)
        return (cv2.GaussianBlur(g, (0, 0), 1.5) - cv2.GaussianBlur(g, (0, 0), 6)).ravel()
    da, db = detail(a), detail(b)
    da, db = da - da.mean(), db - db.mean()
    den = float(np.sqrt(np.dot(da, da) * np.dot(db, db)))
    return float(np.dot(da, db)) / den if den > 0 else 0.0


def same_sheet(names: list[str], metas: list) -> object:
    """The metadata (`scanner.qr.SheetMeta`) that photos `names` share, with the scene's own head from whichever
    photo read its head codes; a UserError naming the first photo that shows another snapshot."""
    from dataclasses import replace

    def key(m):
        return replace(m, head=None)
    heads = {m.head for m in metas if m.head is not None}
    for name, m in zip(names[1:], metas[1:]):
        if key(m) != key(metas[0]):
            raise UserError(f"{name} shows another snapshot than {names[0]} (its QR code names a different scene "
                            f"or codec): give photos of one printed sheet")
    if len(heads) > 1:
        raise UserError(f"the photos' head codes differ ({names[0]} and the rest show different scenes): give photos "
                        f"of one printed sheet")
    return replace(metas[0], head=heads.pop() if heads else None)
