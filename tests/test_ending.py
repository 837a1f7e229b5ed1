"""The fit's last phase chosen by what a print would give (train/field/ending.py): the fork leaves the plain
fit as it was, the channel ending is kept only past the margin, and only where it applies."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from snapshot3d.builtin import builtin_scene
from snapshot3d.errors import UserError
from snapshot3d.scene import dequantize_planes
from snapshot3d.train.field.budget import print_channel
from snapshot3d.train.field.config import FitConfig, check_fit_config
from snapshot3d.train.field.decoder import load_decoder
from snapshot3d.train.field.ending import MARGIN_DB, Ending, ending_noise, fork
from snapshot3d.train.field.fit import fit, hull_grid, new_state


@pytest.fixture(scope="module")
def small():
    posed = builtin_scene("procedural", n_train=12, n_test=3, size=32, seed=1)
    cfg = FitConfig(plane_res=16, plane_channels=4, steps=40, batch_rays=512, occ_warmup=10)
    return posed, load_decoder(), cfg, hull_grid(posed)


def _scorer(channel_bonus: float):
    """A stand-in for the print model: the plain ending (scored first) gets 20 dB, the channel ending
    20 + `channel_bonus`; records the planes it saw."""
    seen = []

    def score(planes, decoder):
        seen.append(planes)
        return 20.0 + (channel_bonus if len(seen) == 2 else 0.0)
    return score, seen


def test_fork_copies_the_state_and_shares_the_ray_bank(small):
    posed, _, cfg, hull = small
    st = new_state(posed, cfg, hull=hull)
    gen = torch.Generator().manual_seed(3)
    twin, twin_gen = fork(st, gen)
    assert twin.bank is st.bank and twin.planes is not st.planes
    twin.planes.planes.data.add_(1.0)
    assert not torch.equal(twin.planes.planes, st.planes.planes)
    assert torch.equal(torch.rand(4, generator=gen), torch.rand(4, generator=twin_gen))


def test_plain_kept_below_the_margin_is_the_plain_fit_itself(small):
    posed, dec, cfg, hull = small
    plain = fit(posed, dec, cfg, hull=hull)
    score, seen = _scorer(MARGIN_DB - 0.01)
    d = ending_noise(16, 4, print_channel())
    got = fit(posed, dec, cfg, hull=hull, ending=Ending(d, score))
    assert got.ending["kept"] == "plain" and len(seen) == 2
    assert got.ending["e2e_expected"] == {"plain": 20.0, "channel": round(20.0 + MARGIN_DB - 0.01, 3)}
    np.testing.assert_array_equal(got.codes, plain.codes)   # the fork does not disturb the plain path
    assert not np.array_equal(seen[0], seen[1])             # the channel ending is another set of planes
    assert plain.ending is None


def test_channel_kept_past_the_margin(small):
    posed, dec, cfg, hull = small
    score, seen = _scorer(MARGIN_DB + 0.01)
    noise = ending_noise(16, 4, print_channel())
    assert torch.equal(ending_noise(16, 4, print_channel(), scale=2.0)[2], 2.0 * noise[2])   # --channel-noise 2
    got = fit(posed, dec, cfg, hull=hull, ending=Ending(noise, score))
    assert got.ending["kept"] == "channel" and got.state.channel is None
    np.testing.assert_array_equal(dequantize_planes(got.codes), seen[1])   # the channel ending's planes
    assert got.state.step == cfg.steps


def test_with_its_own_head_the_channel_ending_is_kept_unless_expected_worse_by_the_margin(small):
    """A head fitted to clean planes makes the views more sensitive to the print than the model sees: with one,
    the channel ending stays unless the model expects it MARGIN_DB worse; the scorer reads the head as carried."""
    from snapshot3d.train.field.head import last_layer
    posed, dec, cfg, hull = small
    d = ending_noise(16, 4, print_channel())
    heads = []
    for bonus, kept in ((-MARGIN_DB + 0.01, "channel"), (-MARGIN_DB - 0.01, "plain")):
        score, seen = _scorer(bonus)

        def spy(planes, decoder, score=score):
            heads.append(last_layer(decoder))
            return score(planes, decoder)
        got = fit(posed, dec, replace(cfg, head="on"), hull=hull, ending=Ending(d, spy))
        assert got.ending["kept"] == kept and got.head is not None
    assert not torch.equal(heads[0], last_layer(dec))   # the scorer saw the scene's own head, not the shared one


def test_no_ending_with_a_background_model_or_a_fixed_channel_phase(small):
    posed, dec, cfg, hull = small
    score, seen = _scorer(5.0)
    d = ending_noise(16, 4, print_channel())
    got = fit(posed, dec, replace(cfg, channel_fraction=0.2), hull=hull, ending=Ending(d, score))
    assert got.ending is None and seen == []


def test_ending_option_is_checked():
    assert FitConfig().ending == "auto"
    with pytest.raises(UserError, match="--ending must be auto or plain"):
        check_fit_config(FitConfig(ending="channel"))


def test_decoder_training_noise_only_at_the_print_ladders_sizes():
    """`train decoder --channel-noise`: the print channel model's noise reaches the planes at a print rung's size
    (16x4), scaled by a draw in [0, S]; other sizes and S = 0 are untouched; a negative S is refused."""
    from snapshot3d.train.field.config import DecoderConfig
    from snapshot3d.train.field.decoder import _channel_noise_fn, train_decoder

    gen, responses = torch.Generator().manual_seed(0), {}
    cfg = DecoderConfig(channel_noise=1.0)
    assert _channel_noise_fn(cfg, 16, 8, responses, gen, None) is None           # no print rung is 16x8
    assert _channel_noise_fn(DecoderConfig(), 16, 4, responses, gen, None) is None
    fn = _channel_noise_fn(cfg, 16, 4, responses, gen, None)
    planes = torch.zeros(3, 4, 16, 16)
    noisy = fn(planes)
    rms = float(noisy.pow(2).mean().sqrt())
    s = responses[(16, 4)][2]
    assert noisy.shape == planes.shape and 0 < rms <= float(s.pow(2).mean().sqrt()) * 1.2, rms
    with pytest.raises(UserError, match="--channel-noise and --plane-noise must be >= 0"):
        train_decoder(DecoderConfig(channel_noise=-1.0), Path("unused.npz"))
    with pytest.raises(UserError, match="--channel-noise and --plane-noise must be >= 0"):
        train_decoder(DecoderConfig(channel_noise=float("nan")), Path("unused.npz"))


def test_decoder_training_starts_from_given_weights(tmp_path):
    """`train decoder --init`: the decoder starts as a copy of a shipped version or a weights file; a width or
    depth other than the config's, a missing file and a file that is not decoder weights are one-line errors,
    raised before any scene is rendered."""
    from snapshot3d.bench.decoder_search import _decoder
    from snapshot3d.train.field.config import DecoderConfig
    from snapshot3d.train.field.decoder import _init_decoder, decoder_path, load_decoder, train_decoder

    got = _init_decoder(DecoderConfig(init="tri-dec-1", hidden=32))
    shipped = load_decoder("tri-dec-1")
    assert all(p.requires_grad for p in got.parameters())
    assert all(torch.equal(a, b) for a, b in zip(got.state_dict().values(), shipped.state_dict().values()))
    same = _init_decoder(DecoderConfig(init=str(decoder_path("tri-dec-1")), hidden=32))
    assert torch.equal(same.l0.weight, shipped.l0.weight)
    with pytest.raises(UserError, match="^--init tri-dec-1 has width 32 and 2 hidden layers: give --hidden 32 "):
        train_decoder(DecoderConfig(init="tri-dec-1"), tmp_path / "d.npz")   # the default width is 64
    with pytest.raises(UserError, match="^--init .*absent.npz: not found"):
        _init_decoder(DecoderConfig(init=str(tmp_path / "absent.npz")))
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(UserError, match="not decoder weights"):
        _init_decoder(DecoderConfig(init=str(junk)))
    # the decoder search reads its candidates the same way
    name, frozen = _decoder(str(decoder_path("tri-dec-1")), "cpu")
    assert name == "tri-dec-1" and not any(p.requires_grad for p in frozen.parameters())
    with pytest.raises(UserError, match="^decoder weights .*junk.npz: not decoder weights"):
        _decoder(str(junk), "cpu")
