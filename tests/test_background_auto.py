"""fit --background auto (the default): a capture without masks in a room gets the background model and the
automatic box; one with masks, or on white, does not (snapshot3d/capture.py). numpy only."""
from __future__ import annotations

import numpy as np
import pytest

from snapshot3d.capture import choose_background, with_overlap_box
from snapshot3d.posed import PosedImages
from snapshot3d.synth_camera import walk_poses


def _posed(images, alpha=None, box_from="from the cameras"):
    n, h, w, _ = images.shape
    c2w = walk_poses(n, np.zeros(3), 1.0, 1.0, np.random.default_rng(0)).astype(np.float32)
    f = w / 2.0
    intr = np.tile(np.array([f, f, w / 2, h / 2], np.float32), (n, 1))
    box = np.array([[-3, -3, -3], [3, 3, 3]], np.float32)
    return PosedImages(images=images.astype(np.float32), alpha=alpha, c2w=c2w, intrinsics=intr, box=box,
                       train=np.arange(n), test=np.arange(0),
                       info={"capture": {"box": box.tolist(), "box_from": box_from}})


def _object_on(background: float, n=6, h=48, w=64):
    img = np.full((n, h, w, 3), background, np.float32)
    img[:, 12:36, 20:44] = (0.6, 0.3, 0.2)
    return img


def test_a_room_gets_the_background_model_and_white_does_not():
    rng = np.random.default_rng(1)
    room = np.clip(_object_on(0.4) + 0.2 * rng.standard_normal((6, 48, 64, 3)), 0, 1)
    mode, why = choose_background(_posed(room))
    assert mode == "outer" and "border is white" in why
    mode, why = choose_background(_posed(_object_on(1.0)))
    assert mode == "white" and "100%" in why
    masked = _posed(_object_on(0.3), alpha=np.ones((6, 48, 64), np.float32))
    assert choose_background(masked) == ("white", "auto: the capture has masks")


@pytest.mark.parametrize("box_from,changes", [("from the cameras", True), ("--box", False),
                                              ("carved from the masks", False)])
def test_the_automatic_box_replaces_only_the_cameras_own(box_from, changes):
    posed = _posed(_object_on(0.4), box_from=box_from)
    out = with_overlap_box(posed)
    assert (not np.array_equal(out.box, posed.box)) == changes
    assert out.info["capture"]["box_from"].startswith("auto") == changes
    if changes:
        assert np.all(out.box[1] - out.box[0] < posed.box[1] - posed.box[0])
        assert out.info["capture"]["box"] == out.box.tolist()
