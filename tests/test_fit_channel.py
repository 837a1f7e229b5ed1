"""The print channel's stand-in for the last phase of a fit (train/field/channel_fit.py): the DCT matches the
codec's, the measured gain and noise reproduce the channel model's error, and the fit option is off by default."""
import numpy as np
import pytest
import torch

from snapshot3d.codecs.print_channel import ChannelModel, predicted_planes
from snapshot3d.codecs.print_source import plane_dct, random_planes
from snapshot3d.errors import UserError
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.train.field.budget import print_channel
from snapshot3d.train.field.channel_fit import channel_response, dct_matrix, stored_responses, through_channel
from snapshot3d.train.field.config import FitConfig, check_fit_config


def test_dct_matrix_is_the_codecs_dct_and_a_clean_channel_is_identity():
    x = random_planes(16, 4, np.random.default_rng(0))
    d = dct_matrix(16)
    coef = (d @ torch.from_numpy(x) @ d.T).numpy()
    assert np.allclose(coef.ravel(), plane_dct(x), atol=1e-5)
    same = through_channel(torch.from_numpy(x), d, torch.ones(16, 16), torch.zeros(16, 16))
    assert np.allclose(same.numpy(), x, atol=1e-5)


def test_the_shipped_responses_are_what_the_channel_gives_now():
    """The responses shipped for the print ladder (channel-responses.npz) are the ones measured now at the
    smallest rung, through budget-curves.json's channel; another channel is measured, not read. After a change to
    the print codec or its channel, write them again: `channel_fit.write_stored_responses(print_channel())`
    (`bench print-predict` does)."""
    from snapshot3d.train.field.config import LADDER_PRINT
    from snapshot3d.train.field.curves import PREDICT_HOSTS

    channel = print_channel()
    assert all(stored_responses(r, c, channel) is not None for r, c in LADDER_PRINT)
    a, s = stored_responses(16, 4, channel)
    fresh_a, fresh_s = channel_response(16, 4, channel, PREDICT_HOSTS)
    assert np.allclose(a, fresh_a, rtol=1e-4, atol=1e-6) and np.allclose(s, fresh_s, rtol=1e-4, atol=1e-6), \
        (np.abs(a - fresh_a).max(), np.abs(s - fresh_s).max())
    assert stored_responses(16, 4, ChannelModel(channel.gain, channel.unit * 2)) is None
    assert stored_responses(20, 4, channel) is None


def test_response_reproduces_the_channel_models_error():
    channel = print_channel()
    a, s = channel_response(16, 4, channel, ["builtin:coffee"], draws=2, seed=1)
    assert a.shape == s.shape == (16, 16) and a.dtype == np.float32
    assert 0.9 < a[0, 0] < 1.1 and 0.9 < a[:4, :4].mean() < 1.05, a[:4, :4]   # low frequencies arrive whole
    assert np.all(s > 0)
    rng = np.random.default_rng(7)
    x = random_planes(16, 4, rng)
    model_rms = float(np.sqrt(np.mean((predicted_planes(load_host("builtin:coffee"), x, channel, rng) - x) ** 2)))
    gen = torch.Generator().manual_seed(0)
    y = through_channel(torch.from_numpy(x), dct_matrix(16), torch.from_numpy(a), torch.from_numpy(s), gen)
    ours_rms = float(torch.sqrt(torch.mean((y - torch.from_numpy(x)) ** 2)))
    assert 0.8 < ours_rms / model_rms < 1.25, (ours_rms, model_rms)


def test_channel_phase_is_off_by_default_and_checked():
    assert FitConfig().channel_fraction == 0.0
    with pytest.raises(UserError, match="--channel-fraction"):
        check_fit_config(FitConfig(channel_fraction=1.5))


def test_the_fits_last_phase_goes_through_the_channel(monkeypatch):
    from snapshot3d.builtin import builtin_scene
    from snapshot3d.scene import dequantize_planes
    from snapshot3d.train.field import channel_fit
    from snapshot3d.train.field import fit as fit_module
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.evaluate import evaluate_planes

    posed = builtin_scene("procedural", n_train=12, n_test=3, size=32, seed=1)
    dec = load_decoder()
    cfg = FitConfig(plane_res=16, plane_channels=4, steps=30, batch_rays=512, occ_warmup=10, channel_fraction=0.5)
    hull = fit_module.hull_grid(posed)
    calls = []

    def spy(planes, *args):
        calls.append(tuple(planes.shape))
        return through_channel(planes, *args)

    # a stand-in response (unit gain, no noise): the phase is then the 8-bit rounding alone
    monkeypatch.setattr(channel_fit, "_cached_response",
                        lambda r, c, channel: (np.ones((r, r), np.float32), np.zeros((r, r), np.float32)))
    monkeypatch.setattr(fit_module, "through_channel", spy)
    res = fit_module.fit(posed, dec, cfg, hull=hull)
    assert calls == [(3, 4, 16, 16)] * 15                     # the last half of 30 steps
    assert res.state.channel is not None and res.state.channel[0].shape == (16, 16)
    clean = evaluate_planes(dequantize_planes(res.codes), dec, posed)["field_psnr"]
    plain = fit_module.fit(posed, dec, FitConfig(**{**cfg.__dict__, "channel_fraction": 0.0}), hull=hull)
    assert len(calls) == 15 and plain.state.channel is None   # off: today's fit
    assert abs(clean - evaluate_planes(dequantize_planes(plain.codes), dec, posed)["field_psnr"]) < 0.5
