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


@pytest.fixture(scope="module")
def plain(tiny):
    """The plain 150-step fit, shared by the tests that score it and that resume to it."""
    return fit(tiny, load_decoder(), CFG)


def test_short_fit_raises_psnr_by_6db(tiny, plain):
    dec = load_decoder()
    before = evaluate_planes(TriPlanes(32, 4, seed=0).planes.detach().numpy(), dec, tiny)["field_psnr"]
    after = evaluate_planes(dequantize_planes(plain.codes), dec, tiny)
    assert after["field_psnr"] > before + 6.0, (before, after["field_psnr"])
    assert after["field_ssim"] > 0.8
    hull, occ = plain.state.occ.hull.float().mean(), plain.state.occ.occ.float().mean()
    assert hull < 0.85 and occ < 0.8 * hull, ("the hull and the learned density should have pruned the box", hull, occ)
    assert plain.codes.shape == (3, 4, 32, 32) and plain.codes.dtype == np.uint8


def test_resume_continues_to_the_same_result(tiny, plain, tmp_path):
    dec = load_decoder()
    ckpt = tmp_path / "run.ckpt"
    with pytest.raises(_Stop):  # a run killed at step 75 (progress comes every 25); its last checkpoint is from step 50
        fit(tiny, dec, CFG, checkpoint=ckpt, progress=_stop_at(75))
    assert torch.load(ckpt, weights_only=False)["step"] == 50
    resumed = fit(tiny, dec, CFG, checkpoint=ckpt)
    assert resumed.state.step == 150
    assert np.array_equal(resumed.codes, plain.codes)


class _Stop(Exception):
    pass


def _stop_at(n):
    def progress(step, psnr):
        if step >= n:
            raise _Stop
    return progress


def test_a_scenes_own_head_is_fitted_carried_and_resumed(tiny, tmp_path):
    """--head on: the head text decodes to the layer the fit ended with (to its codes' step), the scene renders
    better with it than with the shared layer (0.4 dB or more), and a resumed run gives the same head."""
    from dataclasses import replace

    from snapshot3d.head import parse_head
    from snapshot3d.train.field.head import last_layer, with_head
    dec = load_decoder()
    cfg = replace(CFG, head="on")
    res = fit(tiny, dec, cfg)
    step, codes = parse_head(res.head, dec.hidden)
    own = with_head(dec, res.head)
    assert np.abs(last_layer(own) - last_layer(res.state.head)).max() <= step / 2 + 1e-6
    assert np.abs(codes).max() == 127 and torch.equal(last_layer(dec), last_layer(load_decoder()))  # shared untouched
    planes = dequantize_planes(res.codes)
    with_own = evaluate_planes(planes, own, tiny, with_ssim=False)["field_psnr"]
    with_shared = evaluate_planes(planes, dec, tiny, with_ssim=False)["field_psnr"]
    assert with_own > with_shared + 0.4, (with_own, with_shared)   # measured +0.71 dB
    ckpt = tmp_path / "run.ckpt"
    with pytest.raises(_Stop):
        fit(tiny, dec, cfg, checkpoint=ckpt, progress=_stop_at(75))   # killed at 75, resumed from step 50
    resumed = fit(tiny, dec, cfg, checkpoint=ckpt)
    assert resumed.head == res.head and np.array_equal(resumed.codes, res.codes)
