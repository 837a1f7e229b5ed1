"""A small bundle adjustment of a capture's training poses over its photos' matched features (numpy, SciPy and
OpenCV), before the sparse box (`snapshot3d/sparse_box.py`): poses from an app or a solver a little off scatter the
points triangulated from pairs of frames, and the box cut round them misses the object.

The pairwise matches that reproject within `loose_px` at the given poses are joined into tracks (a feature seen in
several frames; a track that holds two features of one frame is dropped), each track is triangulated from all its
frames, and each frame's pose (a turn and a shift of its world-to-camera transform) and each track's point are
adjusted together to their reprojection error: SciPy's `least_squares` with a sparse Jacobian and a robust loss
(soft L1 at `robust_px`), the scheme of COLMAP's and Triggs et al.'s bundle adjustment at a small scale. The given
poses hold the gauge (a similarity the photos cannot see): each pose is drawn back to where it was given with the
weight of `prior_px` pixels per 1/f radian of turn, or 1/f of the cameras' distance of shift. In `passes` passes:
after each but the last, the tracks with an observation more than `trim_px` off at its poses are dropped (the
ground's mirrored tiles match wrongly and agree with one another), and the next pass starts from the given poses.

On the 128x96 composites with 0.5 deg / 1% pose noise (`make-capture --pose-noise-*`), 42 frames: about 1,700 tracks
and 2.5 s; the median pose error falls from 0.45 deg to 0.13-0.17 deg, and the teapot's sparse box holds the object
(it cut through it before). Exact poses move by 0.07 deg (docs/capture-record.md, "A bundle adjustment before the box").
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.transform import Rotation

from .colmap import OPENCV_TO_OPENGL

__all__ = ["BundleConfig", "tracks", "triangulate", "adjust_poses", "projection", "pair_points", "loose_matches"]


@dataclass(frozen=True)
class BundleConfig:
    loose_px: float = 2.0      # a pair's match joins a track where it reprojects within this at the given poses
    robust_px: float = 0.5     # the soft-L1 loss's scale: larger errors count less than their square
    prior_px: float = 1.0      # the gauge: a pose's pull back to where it was given (module docstring)
    max_evaluations: int = 50  # of the residuals by least_squares, a pass
    passes: int = 2            # after each pass but the last, the tracks with an observation off by more than ...
    trim_px: float = 1.0       # ... this are dropped, and the next pass starts again from the given poses
    min_tracks: int = 50       # fewer tracks than this: the poses are left as they are


def tracks(matches: list, counts: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """matches [(i, j, a (K,) int, b (K,) int)]: frame i's feature a[k] is frame j's b[k]; counts: features per
    frame -> (track (O,) int, frame (O,) int, feature (O,) int) per observation, tracks numbered 0..T-1, each seen
    in at least two frames and at most once in each."""
    offset = np.cumsum([0] + list(counts))
    frame_of = np.repeat(np.arange(len(counts)), counts)
    if not matches:
        return (np.zeros(0, int),) * 3
    u = np.concatenate([offset[i] + a for i, _, a, _ in matches])
    v = np.concatenate([offset[j] + b for _, j, _, b in matches])
    graph = coo_matrix((np.ones(len(u)), (u, v)), shape=(offset[-1], offset[-1]))
    _, label = connected_components(graph, directed=False)
    size = np.bincount(label)
    keep = size[label] >= 2
    # a track with one frame twice is a mismatch somewhere along it
    pair, seen = np.unique(label[keep] * len(counts) + frame_of[keep], return_counts=True)
    twice = np.zeros(len(size), bool)
    twice[pair[seen > 1] // len(counts)] = True
    good = keep & ~twice[label]
    feature = np.nonzero(good)[0]
    _, track = np.unique(label[feature], return_inverse=True)
    order = np.argsort(track, kind="stable")
    feature, track = feature[order], track[order]
    return track, frame_of[feature], feature - offset[frame_of[feature]]


def triangulate(track: np.ndarray, pixels: np.ndarray, projections: np.ndarray) -> np.ndarray:
    """track (O,) int sorted, 0..T-1; pixels (O, 2) where each observation is seen; projections (O, 3, 4) of its
    frame -> (T, 3) points, each the linear (DLT) triangulation of all its observations."""
    rows = np.stack([pixels[:, :1] * projections[:, 2] - projections[:, 0],
                     pixels[:, 1:] * projections[:, 2] - projections[:, 1]], axis=1)   # (O, 2, 4)
    rows /= np.maximum(np.linalg.norm(rows, axis=2, keepdims=True), 1e-12)
    starts = np.r_[0, np.nonzero(np.diff(track))[0] + 1, len(track)]
    out = np.zeros((len(starts) - 1, 3))
    for t, (s, e) in enumerate(zip(starts[:-1], starts[1:])):
        h = np.linalg.svd(rows[s:e].reshape(-1, 4))[2][-1]
        out[t] = h[:3] / (h[3] if abs(h[3]) > 1e-12 else 1e-12)
    return out


def _project(rot: np.ndarray, shift: np.ndarray, intr: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per observation: (O, 3, 3) rotations and (O, 3) shifts of OpenCV world-to-camera, (O, 4) (fx, fy, cx, cy),
    (O, 3) points -> (O, 2) pixels."""
    cam = np.einsum("oij,oj->oi", rot, points) + shift
    z = np.where(np.abs(cam[:, 2]) > 1e-9, cam[:, 2], 1e-9)
    return np.c_[intr[:, 0] * cam[:, 0] / z + intr[:, 2], intr[:, 1] * cam[:, 1] / z + intr[:, 3]]


def adjust_poses(c2w: np.ndarray, intrinsics: np.ndarray, track: np.ndarray, frame: np.ndarray,
                 pixels: np.ndarray, cfg: BundleConfig = BundleConfig()) -> tuple[np.ndarray, dict]:
    """c2w (N, 4, 4) OpenGL camera-to-world, intrinsics (N, 4) (fx, fy, cx, cy) in the +0.5 pixel-centre
    convention, and `tracks`' observations with their pixels (O, 2) -> (the adjusted c2w (N, 4, 4) float64, what
    was done for the report). The poses come back as given when there are fewer than cfg.min_tracks tracks. Each
    pose moves by a turn (a rotation vector, applied after the given rotation: small, far from the rotation
    vector's wrap at 180 degrees) and a shift of its world-to-camera transform."""
    c2w = np.asarray(c2w, np.float64)
    m = int(track.max()) + 1 if len(track) else 0
    if m < cfg.min_tracks:
        return c2w, {"tracks": m, "adjusted": False}
    w2c = OPENCV_TO_OPENGL @ np.linalg.inv(c2w)   # the flip is its own inverse
    points = triangulate(track, pixels, _projections(c2w, intrinsics)[frame])
    dist = float(np.median(np.linalg.norm(c2w[:, :3, 3] - points.mean(0), axis=1)))
    weight = cfg.prior_px * float(np.median(intrinsics[:, 0]))
    intr = np.asarray(intrinsics, np.float64)[frame]

    first, keep = None, np.ones(len(track), bool)
    for k in range(cfg.passes):
        kept, sub = np.unique(track[keep], return_inverse=True)
        if k and len(kept) < cfg.min_tracks:
            break
        pose, err = _adjust(w2c, weight, dist, intr[keep], sub, frame[keep], pixels[keep], points[kept], cfg)
        first, used, out = err if first is None else first, len(kept), _c2w(w2c, pose)
        if k + 1 < cfg.passes:   # a track with any observation off, triangulated again at the adjusted poses
            bad = np.zeros(m, bool)
            bad[track[_reprojection(out, intrinsics, track, frame, pixels) > cfg.trim_px]] = True
            keep &= ~bad[track]
    return out, {"tracks": m, "observations": len(track), "adjusted": True,
                 "tracks_last_pass": used,
                 "median_error_px": [round(float(np.median(first[0])), 3), round(float(np.median(err[1])), 3)],
                 "median_turn_deg": round(float(np.degrees(np.median(np.linalg.norm(pose[:, :3], axis=1)))), 3),
                 "median_shift": round(float(np.median(np.linalg.norm(out[:, :3, 3] - c2w[:, :3, 3], axis=1))), 4)}


def _projections(c2w: np.ndarray, intrinsics: np.ndarray) -> np.ndarray:
    """(n, 4, 4) OpenGL camera-to-world and (n, 4) intrinsics -> (n, 3, 4) `projection` matrices."""
    return np.stack([projection(c, k) for c, k in zip(c2w, intrinsics)])


def _reprojection(c2w: np.ndarray, intrinsics: np.ndarray, track: np.ndarray, frame: np.ndarray,
                  pixels: np.ndarray) -> np.ndarray:
    """(n, 4, 4) OpenGL camera-to-world, intrinsics (n, 4), observations -> (O,) pixels between each observation and
    its track's DLT point (`triangulate`) projected."""
    proj = _projections(c2w, intrinsics)[frame]
    points = triangulate(track, pixels, proj)
    q = np.einsum("oij,oj->oi", proj, np.c_[points[track], np.ones(len(track))])
    return np.linalg.norm(q[:, :2] / np.where(np.abs(q[:, 2:]) > 1e-12, q[:, 2:], 1e-12) - pixels, axis=1)


def _c2w(w2c: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(n, 4, 4) OpenCV world-to-camera moved by (n, 6) turns and shifts -> (n, 4, 4) OpenGL camera-to-world."""
    out = np.tile(np.eye(4), (len(w2c), 1, 1))
    out[:, :3, :3], out[:, :3, 3] = _moved(w2c, pose)
    return np.linalg.inv(OPENCV_TO_OPENGL @ out)


def _moved(w2c: np.ndarray, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, 4, 4) world-to-camera and (n, 6) turns and shifts -> (n, 3, 3) rotations and (n, 3) shifts."""
    return Rotation.from_rotvec(pose[:, :3]).as_matrix() @ w2c[:, :3, :3], w2c[:, :3, 3] + pose[:, 3:]


def _adjust(w2c: np.ndarray, weight: float, dist: float, intr: np.ndarray, track: np.ndarray, frame: np.ndarray,
            pixels: np.ndarray, points: np.ndarray,
            cfg: BundleConfig) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """One pass of `adjust_poses` from the given poses w2c (n, 4, 4), the prior's weight per radian and per
    distance `dist`, per observation (O, ...) its intrinsics, track, frame and pixels, and the tracks' first points
    (T, 3) -> ((n, 6) turns and shifts, (each observation's error in pixels (O,) before, after))."""
    n, m, o = len(w2c), len(points), len(track)
    prior = np.r_[np.full(3, weight), np.full(3, weight / dist)]

    def residuals(v):
        (rot, shift), pts = _moved(w2c, v[:6 * n].reshape(n, 6)), v[6 * n:].reshape(m, 3)
        err = (_project(rot[frame], shift[frame], intr, pts[track]) - pixels).ravel()
        return np.r_[err, (prior * v[:6 * n].reshape(n, 6)).ravel()]   # row 2 O + 6 i + k: frame i's k-th

    rows = np.r_[np.repeat(np.arange(2 * o), 6), np.repeat(np.arange(2 * o), 3), 2 * o + np.arange(6 * n)]
    cols = np.r_[(6 * np.repeat(frame, 2)[:, None] + np.arange(6)).ravel(),
                 (6 * n + 3 * np.repeat(track, 2)[:, None] + np.arange(3)).ravel(), np.arange(6 * n)]
    sparsity = coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(2 * o + 6 * n, 6 * n + 3 * m))
    v0 = np.r_[np.zeros(6 * n), points.ravel()]
    res = least_squares(residuals, v0, jac_sparsity=sparsity, x_scale="jac", loss="soft_l1", f_scale=cfg.robust_px,
                        method="trf", max_nfev=cfg.max_evaluations)
    norm = [np.linalg.norm(residuals(v)[:2 * o].reshape(o, 2), axis=1) for v in (v0, res.x)]
    return res.x[:6 * n].reshape(n, 6), (norm[0], norm[1])


def projection(c2w: np.ndarray, intrinsics: np.ndarray) -> np.ndarray:
    """(4, 4) OpenGL camera-to-world and (fx, fy, cx, cy) -> (3, 4) OpenCV projection matrix K [R | t], in the
    intrinsics' own pixel convention (centres at +0.5, `snapshot3d.cameras`)."""
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])
    w2c = OPENCV_TO_OPENGL @ np.linalg.inv(np.asarray(c2w, np.float64))   # the flip is its own inverse
    return k @ w2c[:3]


def pair_points(p_i: np.ndarray, p_j: np.ndarray, x_i: np.ndarray, x_j: np.ndarray,
                max_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Projections (3, 4) of two frames and their matched pixels (2, K) -> (K, 3) triangulated points and (K,) bool:
    in front of both frames and reprojected within max_px in both."""
    h = cv2.triangulatePoints(p_i, p_j, x_i, x_j)
    pts = (h[:3] / np.where(np.abs(h[3]) > 1e-12, h[3], 1e-12)).T
    ok = np.ones(len(pts), bool)
    for p, x in ((p_i, x_i), (p_j, x_j)):
        q = p @ np.c_[pts, np.ones(len(pts))].T
        ok &= (q[2] > 0) & (np.linalg.norm(q[:2] / np.where(q[2] > 0, q[2], 1.0) - x, axis=0) < max_px)
    return pts, ok


def loose_matches(matches: list, keypoints: list, projections: list, cfg: BundleConfig = BundleConfig()) -> list:
    """`tracks`' matches kept where `pair_points` passes them at cfg.loose_px; keypoints: per frame (K, 2) pixels
    (+0.5 convention); projections: per frame (3, 4)."""
    out = []
    for i, j, a, b in matches:
        _, ok = pair_points(projections[i], projections[j], keypoints[i][a].T, keypoints[j][b].T, cfg.loose_px)
        if ok.any():
            out.append((i, j, a[ok], b[ok]))
    return out
