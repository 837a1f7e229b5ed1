"""bench/pose_error.py: how far poses lie from the truth, in pixels of the object's box, checked against poses
moved by a known shift and turn."""
from __future__ import annotations

import cv2
import numpy as np

from snapshot3d.bench.pose_error import pose_error
from snapshot3d.cameras import look_at

BOX = np.array([[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]])
INTR = np.array([[100.0, 100.0, 64.0, 48.0]] * 3)


def _cameras() -> np.ndarray:
    """(3, 4, 4) OpenGL cameras 4 units from the origin, looking at it."""
    eyes = [(4.0, 0.0, 1.0), (0.0, 4.0, 1.0), (-4.0, 0.0, 1.0)]
    return np.stack([look_at(np.array(e), np.zeros(3)) for e in eyes])


def test_the_true_poses_are_zero_pixels_and_zero_degrees_off():
    c2w = _cameras()
    assert pose_error(c2w, c2w, INTR, BOX) == {"px_median": 0.0, "px_mean": 0.0, "px_max": 0.0, "rot_deg_rms": 0.0}


def test_a_sideways_shift_moves_the_box_by_the_focal_length_times_shift_over_depth():
    """Each camera moved 0.04 along its own x axis: points at depth z move by fx * 0.04 / z px, about 1 px at the
    box's centre 4 units away; the rotation is unchanged."""
    c2w = _cameras()
    moved = c2w.copy()
    moved[:, :3, 3] += 0.04 * c2w[:, :3, 0]
    err = pose_error(moved, c2w, INTR, BOX)
    distance = np.linalg.norm(c2w[0, :3, 3])
    assert abs(err["px_median"] - 100.0 * 0.04 / distance) < 0.05, err
    assert err["rot_deg_rms"] == 0.0


def test_a_turn_about_the_camera_is_measured_in_degrees_and_in_pixels():
    """Each camera turned 0.5 degrees about its own y axis: rot_deg_rms 0.5, and every point moves by about
    fx * tan(0.5 deg) = 0.87 px whatever its depth."""
    c2w = _cameras()
    turned = c2w.copy()
    for k in range(len(c2w)):
        turn = cv2.Rodrigues(np.deg2rad(0.5) * c2w[k, :3, 1])[0]
        turned[k, :3, :3] = turn @ c2w[k, :3, :3]
    err = pose_error(turned, c2w, INTR, BOX)
    assert abs(err["rot_deg_rms"] - 0.5) < 1e-3, err
    assert abs(err["px_median"] - 100.0 * np.tan(np.deg2rad(0.5))) < 0.03, err
    assert err["px_max"] >= err["px_median"]
