"""`--up auto` (`capture.cameras_up`): up from upright cameras' level x axes, on views that the mean up misleads."""
import numpy as np
import pytest

from snapshot3d.cameras import look_at
from snapshot3d.capture import cameras_up, up_rotation
from snapshot3d.errors import UserError


def _arc(n, az_deg, el_deg, roll_deg, seed=0):
    """(n, 4, 4) OpenGL c2w looking at the origin of a z-up world from azimuths and elevations drawn uniformly in
    the (lo, hi) degree ranges, each rolled by a normal error of `roll_deg` rms."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        az, el = np.deg2rad(rng.uniform(*az_deg)), np.deg2rad(rng.uniform(*el_deg))
        c2w = look_at(3 * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]), np.zeros(3))
        r = np.deg2rad(roll_deg * rng.standard_normal())
        c2w[:3, :3] = c2w[:3, :3] @ np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1]])
        out.append(c2w)
    return np.stack(out)


def _turned(c2w, rot):
    out = c2w.copy()
    out[:, :3, :] = np.einsum("ij,njk->nik", rot, c2w[:, :3, :])
    return out


def _deg(a, b):
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def test_partial_arc_looking_down():
    # a quarter turn looking down 20-50 degrees, hand-held roll: the mean up leans over 20 degrees toward the object
    rot, _, _ = up_rotation(np.zeros((1, 4, 4)), (0.3, -0.8, 0.52))      # an arbitrary world: z goes elsewhere
    c2w = _turned(_arc(49, (-45, 45), (20, 50), 2.0), rot.T)
    true_up = rot.T @ [0, 0, 1]
    up, how = cameras_up(c2w)
    assert _deg(c2w[:, :3, 1].mean(0), true_up) > 20
    assert _deg(up, true_up) < 1.0 and how == "auto: square to the cameras' level x axes"
    turn, found, _ = up_rotation(c2w, "auto")
    np.testing.assert_allclose(found, up, rtol=1e-9, atol=1e-12)
    assert _deg(turn @ true_up, np.array([0, 0, 1.0])) < 1.0


def test_two_cameras_a_quarter_turn_apart_fix_up():
    # two level x axes fix up as their cross product, where the two views' mean up leans 9 degrees toward the object
    c2w = np.stack([look_at(np.array([3.0, 0, 1]), np.zeros(3)), look_at(np.array([0, 3.0, 1]), np.zeros(3))])
    up, how = cameras_up(c2w)
    np.testing.assert_allclose(up, [0, 0, 1], rtol=1e-9, atol=1e-9)   # arccos near 1 would amplify rounding
    assert how == "auto: square to the cameras' level x axes"
    assert _deg(c2w[:, :3, 1].mean(0), np.array([0, 0, 1.0])) > 5


def test_one_sided_capture_falls_back_to_the_mean_up():
    # views from one side only (x axes within 3 degrees): up is the mean up made square to their x axes
    c2w = _arc(12, (-3, 3), (10, 40), 0.0, seed=1)
    up, how = cameras_up(c2w)
    assert how == "auto: the cameras' mean up, square to their x axes"
    main_x = c2w[:, :3, 0].mean(0)
    assert abs(float(up @ main_x / np.linalg.norm(main_x))) < 1e-3
    mean_up = c2w[:, :3, 1].mean(0)
    assert _deg(up, mean_up) < 5 and up @ mean_up > 0


def test_cameras_with_no_common_up_are_refused():
    c2w = _arc(4, (0, 360), (10, 40), 0.0, seed=2)
    upside_down = c2w @ np.diag([-1.0, -1.0, 1.0, 1.0])      # each view again, turned 180 degrees about its axis
    with pytest.raises(UserError, match="up vectors cancel out"):
        cameras_up(np.concatenate([c2w, upside_down]))
