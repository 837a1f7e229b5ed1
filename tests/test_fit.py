"""Fitting: a few-second fit of a tiny builtin scene raises held-out PSNR by a stated margin; resume."""
import numpy as np
import pytest
import torch

from snapshot3d.builtin import builtin_scene
from snapshot3d.scene import dequantize_planes
from snapshot3d.train.field.config import FitConfig
from snapshot3d.train.field.decoder import load_decoder
from snapshot3d.train.field.evaluate import evaluate_planes
from snapshot3d.train.field.field import TriPlanes
from snapshot3d.train.field.fit import fit

CFG = FitConfig(plane_res=32, plane_channels=4, steps=150, batch_rays=2048, occ_warmup=40, checkpoint_every=50)


@pytest.fixture(scope="module")
def tiny():
    return builtin_scene("procedural", n_train=24, n_test=4, size=48, seed=1)


def test_short_fit_raises_psnr_by_6db(tiny):
    dec = load_decoder()
    before = evaluate_planes(TriPlanes(32, 4, seed=0).planes.detach().numpy(), dec, tiny)["field_psnr"]
    res = fit(tiny, dec, CFG)
    after = evaluate_planes(dequantize_planes(res.codes), dec, tiny)
    assert after["field_psnr"] > before + 6.0, (before, after["field_psnr"])
    assert after["field_ssim"] > 0.8
    hull, occ = res.state.occ.hull.float().mean(), res.state.occ.occ.float().mean()
    assert hull < 0.85 and occ < 0.8 * hull, ("the hull and the learned density should have pruned the box", hull, occ)
    assert res.codes.shape == (3, 4, 32, 32) and res.codes.dtype == np.uint8


def test_resume_continues_to_the_same_result(tiny, tmp_path):
    dec = load_decoder()
    full = fit(tiny, dec, CFG)
    ckpt = tmp_path / "run.ckpt"
    with pytest.raises(_Stop):  # a run killed at step 100; its last checkpoint is from step 50
        fit(tiny, dec, CFG, checkpoint=ckpt, progress=_stop_at(100))
    assert torch.load(ckpt, weights_only=False)["step"] == 50
    resumed = fit(tiny, dec, CFG, checkpoint=ckpt)
    assert resumed.state.step == 150
    assert np.array_equal(resumed.codes, full.codes)


class _Stop(Exception):
    pass


def _stop_at(n):
    def progress(step, psnr):
        if step >= n:
            raise _Stop
    return progress
