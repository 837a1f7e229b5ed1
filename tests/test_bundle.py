"""The small bundle adjustment before the sparse box (snapshot3d/bundle.py): tracks from pairwise matches, their
triangulation, and poses drawn back from noise by the points' reprojection, on synthetic points and cameras."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from snapshot3d.bundle import BundleConfig, adjust_poses, projection, tracks, triangulate
from snapshot3d.synth_camera import perturb_poses

INTR = np.array([140.0, 140.0, 64.0, 48.0])


def _ring(n: int = 24, dist: float = 5.0) -> np.ndarray:
    """(n, 4, 4) OpenGL cameras on a ring 35 deg above the origin, looking at it."""
    out = []
    for a in np.linspace(0, 2 * np.pi, n, endpoint=False):
        pos = dist * np.array([np.cos(a) * np.cos(0.6), np.sin(a) * np.cos(0.6), np.sin(0.6)])
        back = pos / np.linalg.norm(pos)                      # OpenGL: the camera looks along -z
        right = np.cross([0.0, 0.0, 1.0], back)
        right /= np.linalg.norm(right)
        c2w = np.eye(4)
        c2w[:3, :3] = np.stack([right, np.cross(back, right), back], axis=1)
        c2w[:3, 3] = pos
        out.append(c2w)
    return np.stack(out)


def _observe(c2w: np.ndarray, points: np.ndarray, rng, noise_px: float = 0.1):
    """Each point seen by the cameras that face it within the frame -> (track, frame, pixels (O, 2))."""
    track, frame, pixels = [], [], []
    for f, c in enumerate(c2w):
        q = projection(c, INTR) @ np.c_[points, np.ones(len(points))].T
        px = (q[:2] / q[2]).T
        seen = (q[2] > 0) & np.all((px > 0) & (px < [128, 96]), axis=1)
        seen &= (points - c[:3, 3]) @ -c[:3, 2] > 0
        facing = points[:, :2] @ c[:2, 3] > 0        # the ring's near half sees a point (an opaque object)
        keep = np.nonzero(seen & facing)[0]
        track.append(keep), frame.append(np.full(len(keep), f))
        pixels.append(px[keep] + rng.normal(0, noise_px, (len(keep), 2)))
    track, frame, pixels = np.concatenate(track), np.concatenate(frame), np.concatenate(pixels)
    order = np.argsort(track, kind="stable")
    return track[order], frame[order], pixels[order]


def _turns_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.linalg.norm((Rotation.from_matrix(a[:, :3, :3]) *
                                      Rotation.from_matrix(b[:, :3, :3]).inv()).as_rotvec(), axis=1))


def test_tracks_join_matches_across_frames_and_drop_a_track_that_holds_one_frame_twice():
    counts = [4, 4, 4]
    matches = [(0, 1, np.array([0, 1, 2]), np.array([0, 1, 3])),
               (1, 2, np.array([0, 1, 2]), np.array([0, 1, 1]))]   # frame 2's feature 1 takes frame 1's 1 and 2
    track, frame, feature = tracks(matches, counts)
    got = sorted(tuple(sorted(zip(frame[track == t].tolist(), feature[track == t].tolist())))
                 for t in range(track.max() + 1))
    # frames 0-1-2 through features (0, 0, 0); (0:2, 1:3) a pair; the one through frame 1's 1 and 2 is dropped
    assert got == [((0, 0), (1, 0), (2, 0)), ((0, 2), (1, 3))]
    assert np.all(np.diff(track) >= 0)
    assert all(len(x) == 0 for x in tracks([], counts))


def test_triangulate_recovers_points_from_their_exact_projections():
    rng = np.random.default_rng(0)
    c2w, points = _ring(), rng.uniform(-0.8, 0.8, (200, 3))
    track, frame, pixels = _observe(c2w, points, rng, noise_px=0.0)
    proj = np.stack([projection(c, INTR) for c in c2w])
    got = triangulate(track, pixels, proj[frame])
    want = points[np.unique(track)]
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1])
def test_adjusted_poses_lie_nearer_the_truth_than_poses_half_a_degree_off(seed):
    """24 cameras a ring, 600 points seen with 0.1 px of noise; poses written 0.5 deg / 1% off: after the
    adjustment the median turn against the truth is at most half the given one, and every frame gains."""
    rng = np.random.default_rng(seed)
    true, points = _ring(), rng.uniform(-0.8, 0.8, (600, 3))
    track, frame, pixels = _observe(true, points, rng)
    _, track = np.unique(track, return_inverse=True)
    given = perturb_poses(true, np.zeros(3), 0.5, 0.01, rng)
    out, info = adjust_poses(given, np.tile(INTR, (len(true), 1)), track, frame, pixels)
    before, after = _turns_deg(given, true), _turns_deg(out, true)
    assert info["adjusted"] and info["median_error_px"][1] < 0.5 * info["median_error_px"][0]
    assert np.median(after) <= 0.5 * np.median(before), (np.median(before), np.median(after))
    shift_before = np.linalg.norm(given[:, :3, 3] - true[:, :3, 3], axis=1)
    shift_after = np.linalg.norm(out[:, :3, 3] - true[:, :3, 3], axis=1)
    assert np.median(shift_after) <= 0.75 * np.median(shift_before)


def test_exact_poses_stay_put_and_too_few_tracks_leave_the_poses_as_given():
    rng = np.random.default_rng(2)
    true, points = _ring(), rng.uniform(-0.8, 0.8, (600, 3))
    track, frame, pixels = _observe(true, points, rng)
    _, track = np.unique(track, return_inverse=True)
    out, _ = adjust_poses(true, np.tile(INTR, (len(true), 1)), track, frame, pixels)
    assert np.max(_turns_deg(out, true)) < 0.05
    few = track < 10
    same, info = adjust_poses(true, np.tile(INTR, (len(true), 1)), track[few], frame[few], pixels[few],
                              BundleConfig(min_tracks=50))
    assert not info["adjusted"] and np.array_equal(same, true)


@pytest.mark.parametrize("layout, refine, bundle", [("nerfstudio", "on", "fit"), ("colmap", "on", "fit"),
                                                    ("blender", "off", "off"), ("builtin", "off", "off")])
def test_bundle_auto_follows_the_pose_refinement(layout, refine, bundle):
    """--bundle auto adjusts the poses to the photos' matches where the fit refines them (captures from a solver or
    an app), not where they are exact; given values stay as given."""
    from snapshot3d.train.field.commands import resolve_autos
    from snapshot3d.train.field.config import FitConfig

    cfg = resolve_autos(FitConfig(), layout, None)
    assert (cfg.refine_poses, cfg.bundle) == (refine, bundle)
    assert resolve_autos(FitConfig(refine_poses="on"), "blender", None).bundle == "fit"
    assert resolve_autos(FitConfig(bundle="box"), layout, None).bundle == "box"
