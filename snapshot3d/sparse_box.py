"""The box of a capture without masks from its photos' sparse 3D points (numpy and OpenCV; fit --box auto with the
background model): what COLMAP's sparse model holds, found here with the capture's own poses.

SIFT features of each training frame are matched (ratio test) with those of its nearest cameras (with `bundle`, the
poses are first adjusted to those matches, `snapshot3d/bundle.py`), triangulated, and kept where they reproject within
`reproj_px` in both frames with at least `min_parallax_deg` between the rays. Under the cameras' look-at point, the
plane that holds the most points in a band of `tolerance` is the ground (RANSAC, a fixed seed) if it lies within
`max_tilt_deg` of horizontal; where poses a little off scatter the points, the band widens (`spread`). The points
above it inside the first box, less the stray ones (`knn`), are the object's. The box is cut round them: their
`quantile` and 1 - `quantile` on each axis, widened by `margin` of the span and `pad` of the first box (the points
miss the object's untextured parts), the floor `floor_lift` over the plane (a fit's ground is not thinner). None when
the points do not show a ground with an object on it; the fit then finds them from a short fit's density
(`train/field/box_tighten.py`).

On the 128x96 composites of spot and duck (seeds 0-2), teapot, bunny and suzanne (0), 4,000 to 8,000 points a
capture in about a second: the ground within 0.004 of the truth on all nine, and each box holds the object's true
box, where the density rule put spot's seed-1 ground at -1.52 (true -0.98; docs/capture.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .bundle import BundleConfig, adjust_poses, loose_matches, pair_points, projection, tracks

__all__ = ["SparseBoxConfig", "features", "points_from_matches", "sparse_points", "adjusted_poses", "find_ground",
           "box_from_points", "ground_pixels", "sparse_box"]


@dataclass(frozen=True)
class SparseBoxConfig:
    neighbours: int = 8            # each frame is matched with its nearest cameras ...
    max_turn_deg: float = 45.0     # ... whose optical axes turn by at most this
    features: int = 2000           # SIFT features a frame
    ratio: float = 0.8             # Lowe's ratio test
    reproj_px: float = 1.0         # a triangulated point reprojects within this in both frames
    min_parallax_deg: float = 2.0  # and its two rays meet at least at this angle
    max_tilt_deg: float = 20.0     # the ground's normal within this of +z
    tolerance: float = 0.02        # a point on a plane: within this share of the first box's half-size
    min_ground_share: float = 0.2  # the ground holds this share of the points under the look-at point
    max_below_share: float = 0.1   # and at most this share lie below it (an opaque floor hides what is under)
    min_points: int = 30           # points the ground and the object each need
    knn: int = 5                   # the object's points: those whose knn-th nearest lies within ...
    knn_radius: float = 0.15       # ... this share of the first box's half-size (stray matches lie apart)
    max_object_points: int = 4000  # a larger object's points are subsampled to this first (fixed seed)
    quantile: float = 0.01         # the object's extent: these quantiles of its points ...
    margin: float = 0.25           # ... widened by this share of their span (the points miss untextured parts) ...
    pad: float = 0.1               # ... and this share of the first box's half-size
    floor_lift: float = 0.026      # the floor: this share of the half-size over the ground (0.042 on spot; measured)
    iterations: int = 400          # RANSAC draws
    spread: tuple = (1, 2, 3)      # the band is widened by these factors in turn until a plane passes: points from
    #                                poses a little off scatter about the ground (0.5 deg: 17% within 1x of it)
    bundle: bool = True            # adjust the poses to the matches first (`snapshot3d.bundle`): poses a little off
    #                                scatter the points (0.5 deg: the teapot's box cut through it without)
    scatter_trigger: float = 0.95  # the rule below applies where this quantile of the points under the ground lies
    #                                deeper than three bands (0.95: 5% of them)
    scatter_quantile: float = 0.99  # where 5% of the points under the ground lie deeper than the object's points
    #                                must rise, they must rise higher than this quantile of those depths


def _pairs(c2w: np.ndarray, cfg: SparseBoxConfig) -> list[tuple[int, int]]:
    """Index pairs (i < j) of each camera with its `neighbours` nearest whose axes turn by at most max_turn_deg."""
    pos, axis = c2w[:, :3, 3], -c2w[:, :3, 2]
    axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    dist = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    dist[axis @ axis.T < np.cos(np.radians(cfg.max_turn_deg))] = np.inf
    np.fill_diagonal(dist, np.inf)
    out = set()
    for i in range(len(c2w)):
        for j in np.argsort(dist[i])[:cfg.neighbours]:
            if np.isfinite(dist[i, j]):
                out.add((min(i, int(j)), max(i, int(j))))
    return sorted(out)


def features(images: np.ndarray, c2w: np.ndarray, cfg: SparseBoxConfig = SparseBoxConfig()) -> tuple[list, list]:
    """images (N, H, W, 3) float32 RGB in [0, 1], c2w (N, 4, 4) OpenGL -> (per frame its SIFT keypoints (K, 2)
    float64 in the +0.5 pixel-centre convention of `snapshot3d.cameras`, and the matches [(i, j, a (M,), b (M,))]:
    frame i's keypoint a[k] is frame j's b[k], for each pair of near cameras (ratio test))."""
    # precise upscale: SIFT's first octave maps pixel x to 2x; OpenCV's default upscale shifts keypoints by about a
    # quarter pixel (opencv/opencv#23123), which put the ground found 0.01 off on the composites (docs/capture.md)
    sift = cv2.SIFT_create(nfeatures=cfg.features, contrastThreshold=0.01, enable_precise_upscale=True)
    found = [sift.detectAndCompute(cv2.cvtColor(np.clip(im * 255 + 0.5, 0, 255).astype(np.uint8), cv2.COLOR_RGB2GRAY),
                                   None) for im in images]
    keypoints = [np.float64([k.pt for k in kp]).reshape(-1, 2) + 0.5 for kp, _ in found]   # OpenCV's centres: +0.5
    matcher, matches = cv2.BFMatcher(cv2.NORM_L2), []
    for i, j in _pairs(np.asarray(c2w, np.float64), cfg):
        di, dj = found[i][1], found[j][1]
        if di is None or dj is None or len(di) < 2 or len(dj) < 2:
            continue
        good = [m[0] for m in matcher.knnMatch(di, dj, k=2)
                if len(m) == 2 and m[0].distance < cfg.ratio * m[1].distance]
        if len(good) >= 8:
            matches.append((i, j, np.array([g.queryIdx for g in good]), np.array([g.trainIdx for g in good])))
    return keypoints, matches


def points_from_matches(keypoints: list, matches: list, c2w: np.ndarray, intrinsics: np.ndarray,
                        cfg: SparseBoxConfig = SparseBoxConfig(), with_pixels: bool = False):
    """`features`' keypoints and matches, c2w (N, 4, 4) OpenGL, intrinsics (N, 4) -> (M, 3) float64 world points,
    one a match, kept where they reproject within reproj_px in both frames with min_parallax_deg between the rays;
    with `with_pixels`, also where each was seen: (M, 2, 3) float64, (frame, x, y) in each of its two frames
    (`features`' pixel convention)."""
    proj, out, seen = [projection(c, k) for c, k in zip(c2w, intrinsics)], [], []
    for i, j, a, b in matches:
        pts, ok = pair_points(proj[i], proj[j], keypoints[i][a].T, keypoints[j][b].T, cfg.reproj_px)
        u, v = pts - c2w[i, :3, 3], pts - c2w[j, :3, 3]
        cos = (u * v).sum(1) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1), 1e-12)
        keep = ok & (cos < np.cos(np.radians(cfg.min_parallax_deg)))
        out.append(pts[keep])
        seen.append(np.stack([np.column_stack([np.full(int(keep.sum()), f, np.float64), keypoints[f][k][keep]])
                              for f, k in ((i, a), (j, b))], axis=1))
    points = np.concatenate(out) if out else np.zeros((0, 3))
    return (points, np.concatenate(seen) if seen else np.zeros((0, 2, 3))) if with_pixels else points


def ground_pixels(points: np.ndarray, seen: np.ndarray, plane, band: float, size: tuple) -> np.ndarray:
    """points (M, 3) world, where each was seen (M, 2, 3) (`points_from_matches`), the ground plane z = a x + b y + c
    and its band's half-width -> (K, 3) int64 (frame, row, col), unique, of the pixels of frames of `size`
    (height, width) that show a point within the band of the ground: their rays pass the box above the ground."""
    a, b, c = plane
    on = np.abs(points[:, 2] - a * points[:, 0] - b * points[:, 1] - c) <= band
    px = seen[on].reshape(-1, 3)
    frame, col, row = px[:, 0].astype(np.int64), np.floor(px[:, 1]).astype(np.int64), np.floor(px[:, 2]).astype(np.int64)
    ok = (row >= 0) & (row < size[0]) & (col >= 0) & (col < size[1])
    return np.unique(np.column_stack([frame, row, col])[ok], axis=0)


def sparse_points(images: np.ndarray, c2w: np.ndarray, intrinsics: np.ndarray,
                  cfg: SparseBoxConfig = SparseBoxConfig()) -> np.ndarray:
    """images (N, H, W, 3) float32 RGB in [0, 1], c2w (N, 4, 4) OpenGL, intrinsics (N, 4) (fx, fy, cx, cy) of
    undistorted frames -> (M, 3) float64 world points triangulated from matched SIFT features (M may be 0)."""
    keypoints, matches = features(images, c2w, cfg)
    return points_from_matches(keypoints, matches, np.asarray(c2w, np.float64), intrinsics, cfg)


def adjusted_poses(keypoints: list, matches: list, c2w: np.ndarray, intrinsics: np.ndarray,
                   cfg: BundleConfig = BundleConfig()) -> tuple[np.ndarray, dict]:
    """`features`' keypoints and matches at the poses c2w (N, 4, 4) OpenGL, intrinsics (N, 4) -> the poses after
    `snapshot3d.bundle.adjust_poses` over the matches' tracks (N, 4, 4) float64, and its report."""
    c2w = np.asarray(c2w, np.float64)
    loose = loose_matches(matches, keypoints, [projection(c, k) for c, k in zip(c2w, intrinsics)], cfg)
    track, frame, feature = tracks(loose, [len(k) for k in keypoints])
    offset = np.cumsum([0] + [len(k) for k in keypoints])
    pixels = np.concatenate(keypoints)[offset[frame] + feature]
    return adjust_poses(c2w, intrinsics, track, frame, pixels, cfg)


def find_ground(points: np.ndarray, box: np.ndarray, cfg: SparseBoxConfig = SparseBoxConfig()):
    """points (M, 3) world; box (2, 3) the first box (its centre the cameras' look-at point) -> ((a, b, c) of the
    ground plane z = a x + b y + c, its points' mask (M,) bool, the band's factor of `spread`), or None when no
    plane under the look-at point within max_tilt_deg of horizontal holds min_ground_share of the points there with
    at most max_below_share of them below it, at any band of `spread`."""
    box = np.asarray(box, np.float64)
    centre, half = box.mean(0), float((box[1] - box[0]).max()) / 2
    under = np.all((points[:, :2] >= box[0, :2]) & (points[:, :2] <= box[1, :2]), axis=1) & (points[:, 2] < centre[2])
    low = points[under]
    if len(low) < cfg.min_points:
        return None
    for factor in cfg.spread:
        found = _ground_plane(low, factor * cfg.tolerance * half, cfg)
        if found is not None:
            plane, on_low = found
            mask = np.zeros(len(points), bool)
            mask[np.nonzero(under)[0][on_low]] = True
            return plane, mask, factor
    return None


def _ground_plane(low: np.ndarray, tol: float, cfg: SparseBoxConfig):
    """The points under the look-at point (L, 3) and the band's half-width `tol` -> ((a, b, c), the points on it
    (L,) bool) or None (`find_ground`'s tests)."""
    rng = np.random.default_rng(0)
    best, best_n = None, 0
    for _ in range(cfg.iterations):   # any plane up to 60 degrees: a steeper floor must win, then be refused
        p = low[rng.choice(len(low), 3, replace=False)]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        if np.linalg.norm(n) < 1e-12 or abs(n[2]) / np.linalg.norm(n) < 0.5:
            continue
        n = n / np.linalg.norm(n)
        count = int(np.sum(np.abs((low - p[0]) @ n) < tol))
        if count > best_n:
            best, best_n = (n, p[0]), count
    if best is None:
        return None
    n, p0 = best
    near = np.abs((low - p0) @ n) < tol
    for _ in range(2):   # least squares on the inliers, twice
        plane = np.linalg.lstsq(np.c_[low[near, :2], np.ones(near.sum())], low[near, 2], rcond=None)[0]
        near = np.abs(low[:, 2] - low[:, :2] @ plane[:2] - plane[2]) < tol
    resid = low[:, 2] - low[:, :2] @ plane[:2] - plane[2]
    if np.mean(np.abs(resid) < tol) < cfg.min_ground_share or np.mean(resid < -3 * tol) > cfg.max_below_share or \
            np.hypot(plane[0], plane[1]) > np.tan(np.radians(cfg.max_tilt_deg)):
        return None
    return tuple(float(v) for v in plane), np.abs(resid) < tol


def _clustered(points: np.ndarray, radius: float, cfg: SparseBoxConfig) -> np.ndarray:
    """points (M, 3) -> those whose knn-th nearest point lies within `radius`."""
    if len(points) > cfg.max_object_points:
        points = points[np.random.default_rng(0).choice(len(points), cfg.max_object_points, replace=False)]
    if len(points) <= cfg.knn:
        return points
    chunks = np.array_split(points, max(1, len(points) // 500))
    kth = np.concatenate([np.partition(np.linalg.norm(c[:, None] - points[None], axis=2), cfg.knn, axis=1)[:, cfg.knn]
                          for c in chunks])
    return points[kth <= radius]


def sparse_box(images: np.ndarray, c2w: np.ndarray, intrinsics: np.ndarray, box: np.ndarray,
               cfg: SparseBoxConfig = SparseBoxConfig()) -> tuple[np.ndarray | None, dict, np.ndarray]:
    """Training frames (`sparse_points`' layout) and the first box (2, 3) -> (the box (2, 3) float32 cut at the
    ground and round the object's points, or None; what was found, for the report; the poses (N, 4, 4) float64 the
    points were triangulated at: after the bundle adjustment with cfg.bundle, else c2w)."""
    keypoints, matches = features(images, c2w, cfg)
    c2w, adjusted = np.asarray(c2w, np.float64), None
    if cfg.bundle:
        c2w, adjusted = adjusted_poses(keypoints, matches, c2w, intrinsics)
    points, seen = points_from_matches(keypoints, matches, c2w, intrinsics, cfg, with_pixels=True)
    out, info = box_from_points(points, box, cfg)
    band = info.pop("ground_band_width", None)
    if out is not None:   # the pixels that show the ground, for the fit (fit --seen-ground-weight); their rays are
        # empty above the band's top, with the band's width again to spare (a feature on the object's own base)
        info.update(ground_pixels=ground_pixels(points, seen, info["ground_plane"], band, images.shape[1:3]),
                    ground_clear=round(2 * band, 4))
    return out, {**info, **({"bundle": adjusted} if adjusted else {})}, c2w


def box_from_points(points: np.ndarray, box: np.ndarray,
                    cfg: SparseBoxConfig = SparseBoxConfig()) -> tuple[np.ndarray | None, dict]:
    """points (M, 3) world and the first box (2, 3) -> `sparse_box`'s (box or None, info)."""
    info = {"sparse_points": int(len(points))}
    box = np.asarray(box, np.float64)
    ground = find_ground(points, box, cfg) if len(points) else None
    if ground is None:
        return None, {**info, "sparse_ground": None}
    (a, b, c), on_ground, factor = ground
    centre, half = box.mean(0), float((box[1] - box[0]).max()) / 2
    ground_z = float(a * centre[0] + b * centre[1] + c)
    height = points[:, 2] - points[:, :2] @ np.array([a, b]) - c
    inside = np.all((points >= box[0]) & (points <= box[1]), axis=1)
    above = 3 * factor * cfg.tolerance * half
    under = -height[inside & (height < 0)]   # under an opaque ground lies only its scatter, and as much lies over it
    if len(under) and np.quantile(under, cfg.scatter_trigger) > above:   # scattered points (poses a little off)
        above = float(np.quantile(under, cfg.scatter_quantile))
    obj = _clustered(points[inside & (height > above)], cfg.knn_radius * half, cfg)
    info.update(sparse_ground=round(ground_z, 4), ground_points=int(on_ground.sum()), object_points=int(len(obj)),
                ground_tilt_deg=round(float(np.degrees(np.arctan(np.hypot(a, b)))), 2), ground_band=factor,
                ground_plane=[float(a), float(b), float(c)], ground_band_width=factor * cfg.tolerance * half)
    if len(obj) < cfg.min_points:
        return None, info
    lo, hi = np.quantile(obj, cfg.quantile, axis=0), np.quantile(obj, 1 - cfg.quantile, axis=0)
    grow = cfg.margin * (hi - lo) + cfg.pad * half
    out = np.stack([np.maximum(box[0], lo - grow), np.minimum(box[1], hi + grow)])
    # where the band had to widen, the plane itself: the plane of many scattered points lies near the ground all
    # the same, and a floor above it would cut the object's base
    out[0, 2] = max(box[0, 2], ground_z + (cfg.floor_lift * half if factor == cfg.spread[0] else 0.0))
    if not np.all(out[1] > out[0]):
        return None, info
    return out.astype(np.float32), info
