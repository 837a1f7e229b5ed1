"""Codec training: a few steps of a tiny network on the shipped scene; the z loss does what it says."""
import shutil

import pytest

from snapshot3d.paths import asset
from snapshot3d.train.codec.config import CodecConfig
from snapshot3d.train.codec.data import load_codec_data
from snapshot3d.train.codec.training import train_codec

TINY = dict(blocks=1, width=8, layers=2, steps=50, batch=2, crop=32, lr=3e-3, full_every=0, ramp=0.0,
            holdout_scenes="", checkpoint_every=1000)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    scenes = tmp_path_factory.mktemp("scenes")
    shutil.copy(asset("spot.s3d"), scenes / "spot.s3d")
    return load_codec_data(scenes, set(), {"coffee", "chelsea"})


def _last_z_mse(data, tmp_path, z_weight: float) -> float:
    run = train_codec(CodecConfig(**TINY, z_weight=z_weight), data, tmp_path / f"z{z_weight}.npz", log=lambda _: None)
    assert (tmp_path / f"z{z_weight}.npz").is_file()
    return run["history"][-1]["z_mse"]


def test_z_loss_pulls_the_lost_part_to_the_constant(data, tmp_path):
    free, pulled = _last_z_mse(data, tmp_path, 0.0), _last_z_mse(data, tmp_path, 20.0)
    assert pulled < 0.5 * free, (free, pulled)


def test_fine_tune_starts_at_the_host_weight_its_init_ended_with(data, tmp_path):
    import json
    import math

    from snapshot3d.train.codec.training import initial_host_logw
    first = tmp_path / "first.npz"
    train_codec(CodecConfig(**{**TINY, "steps": 2}), data, first, log=lambda _: None)
    assert initial_host_logw(str(first)) == 0.0  # no summary beside it: weight 1, as from scratch
    first.with_suffix(".json").write_text(json.dumps({"history": [{"host_weight": 20.0}]}))
    assert math.isclose(initial_host_logw(str(first)), math.log(20.0))
    run = train_codec(CodecConfig(**{**TINY, "steps": 1, "init": str(first)}), data, tmp_path / "tuned.npz",
                      log=lambda _: None)
    assert 20.0 * math.exp(-0.06) < run["history"][-1]["host_weight"] < 20.0 * math.exp(0.06)
    first.with_suffix(".json").write_text("{not json")
    assert initial_host_logw(str(first)) == 0.0
