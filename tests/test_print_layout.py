"""The print medium's carriers (`snapshot3d.codecs.print_*`, `snapshot3d.codecs.bands`): the band split is
orthonormal, carriers are disjoint and unit-norm, an embedded snapshot reads back exactly, the host
fidelity lands where it is asked, and the pilots' estimate of the error tracks the true error."""
import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.codecs import bands, print_carriers, print_embed, print_read, print_source
from snapshot3d.errors import UserError
from snapshot3d.scanner.backgrounds import load_host

N = formats.SNAPSHOT_SIZE


def test_bands_are_orthonormal_and_invert(rng):
    img = rng.random((N, N, 3))
    b = bands.analyse(img)
    assert set(b) == set(bands.ALL_BANDS)
    assert np.abs(bands.synthesise(b) - img).max() < 1e-12
    assert abs(sum(float((v ** 2).sum()) for v in b.values()) - float((img ** 2).sum())) < 1e-6 * img.size
    assert b["Y3LH"].shape == (47, 47) and b["Y2HH"].shape == (95, 95) and b["Y1LH"].shape == (190, 190)
    with pytest.raises(ValueError, match="multiples of 4"):
        bands.analyse(np.zeros((10, 10, 3)))


def test_allocation_spends_the_budget_where_it_pays():
    lam = np.array([10.0, 1.0, 0.1, 1e-6])
    p = print_source.allocate(lam, total=2.0, noise=0.1)
    assert abs(p.sum() - 2.0) < 1e-9 and p[0] > p[1] > p[2] and p[3] == 0.0


@pytest.mark.parametrize("res,channels", [(32, 4), (16, 4), (64, 8)])
def test_carriers_are_disjoint(res, channels):
    lay = print_carriers.print_layout(res, channels)
    assert len(np.unique(lay.chips)) == lay.chips.size            # no coefficient serves two carriers
    assert lay.carriers == print_carriers.PILOTS + len(lay.coef) + 2 * len(lay.folded) and lay.chips.shape[1] >= 1
    assert len(lay.coef) <= 3 * channels * res * res


def test_refuses_planes_it_cannot_carry():
    with pytest.raises(ValueError, match="print codec carries planes"):
        print_source.check_print_planes(4, 80)
    with pytest.raises(ValueError, match="print codec carries planes"):
        print_source.check_print_planes(13, 32)


@pytest.fixture(scope="module")
def embedded():
    rng = np.random.default_rng(1)
    planes = print_source.random_planes(32, 4, rng)
    host = load_host("builtin:chelsea")
    return host, planes, print_embed.embed(host, planes, 32.0)


def test_host_fidelity_lands_on_the_target(embedded):
    host, planes, snap = embedded
    host8 = np.round(host * 255) / 255
    mse = np.mean((snap / 255.0 - host8) ** 2)
    assert snap.dtype == np.uint8 and snap.shape == (N, N, 3)
    assert abs(-10 * np.log10(mse) - 32.0) < 0.1


def test_a_lossless_snapshot_reads_back_every_carrier(embedded):
    """The carriers the encoder wrote are what a linear reading of the 8-bit file finds (up to rounding
    and the host's own projection, which the designed encoder leaves and the pilots count as noise)."""
    host, planes, snap = embedded
    lay = print_carriers.print_layout(32, 4)
    target = print_embed.carrier_values(lay, planes)
    read, factor = print_read.despread(snap, 32, 4)
    gain = np.mean(read[:print_carriers.PILOTS] * lay.pilot_signs) / lay.pilot_amp
    # the pilots carry the payload's scale: the readings are the target values times that scale, plus noise
    assert gain > 0 and np.corrcoef(read, target)[0, 1] > 0.5
    est, reading = print_read.restore(read, factor, 32, 4)
    true_rmse = float(np.sqrt(np.mean((est - planes) ** 2)))
    assert true_rmse < 0.5 * planes.std()
    assert 0.6 < reading.plane_rmse / true_rmse < 1.6   # the pilots predict the error without ground truth


def test_pilots_see_added_noise(embedded):
    """More channel noise: the pilots report more noise and a larger expected error, as the truth has it."""
    host, planes, snap = embedded
    rng = np.random.default_rng(3)
    out = []
    for sigma in (0.0, 8.0, 20.0):
        noisy = np.clip(snap + rng.normal(0, sigma, snap.shape), 0, 255).astype(np.uint8)
        est, reading = print_read.restore(*print_read.despread(noisy, 32, 4), 32, 4)
        out.append((reading.noise, reading.plane_rmse, float(np.sqrt(np.mean((est - planes) ** 2)))))
    assert out[0][0] < out[1][0] < out[2][0]
    assert out[0][2] < out[1][2] < out[2][2]
    for noise, expected, true in out:
        assert 0.6 < expected / true < 1.6


def test_print_front_end_trains_and_resumes(tmp_path):
    """`train print-codec`'s loop on stand-in captures (a snapshot plus noise): it writes weights that load,
    and a second run resumes from the checkpoint instead of starting again."""
    from snapshot3d.train.codec.print_train import PrintCodecConfig, load_front_end, train_print_codec

    rng = np.random.default_rng(0)
    snaps = rng.integers(0, 256, (6, 380, 380, 3), dtype=np.uint8)
    caps = np.clip(snaps + rng.normal(0, 8, snaps.shape), 0, 255).astype(np.uint8)
    cfg = PrintCodecConfig(width=8, depth=1, steps=2, batch=2, crop=64, captures=6, checkpoint_every=1)
    out, ck, logs = tmp_path / "front.npz", tmp_path / "front.npz.ckpt", []
    s = train_print_codec(cfg, caps, snaps, out, checkpoint=ck, log=logs.append)
    assert s["steps"] == 2 and s["held_out"]["held_out_loss"] > 0 and out.is_file() and ck.is_file()
    net, back = load_front_end(out)
    assert back == cfg
    x = np.random.default_rng(1).uniform(0, 1, (1, 3, 64, 64)).astype(np.float32)
    import torch
    assert net(torch.from_numpy(x)).shape == (1, 3, 64, 64)
    logs.clear()
    from dataclasses import replace
    s = train_print_codec(replace(cfg, steps=3), caps, snaps, out, checkpoint=ck, log=logs.append)
    assert s["steps"] == 3 and "resumed at step 2" in logs
    with pytest.raises(UserError, match="other settings"):
        train_print_codec(replace(cfg, lr=0.5), caps, snaps, out, checkpoint=ck, log=logs.append)


def _rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


def test_bands_are_combined_as_the_capture_kept_them(embedded):
    """A capture that lost one band (the finest luma: attenuated and drowned in noise, as lens blur and the
    print do) restores better when the pilots weigh the bands than with the designed filters; a clean copy
    restores at least as well; the combined readings keep the plain readings' scale (the pilots' gain)."""
    host, planes, snap = embedded
    rng = np.random.default_rng(5)
    coeffs = bands.analyse(snap / 255.0)
    for b in ("Y1LH", "Y1HL"):
        coeffs[b] = 0.2 * coeffs[b] + rng.normal(0, 0.1, coeffs[b].shape)
    lossy = np.clip(np.round(bands.synthesise(coeffs) * 255), 0, 255).astype(np.uint8)
    err = {}
    for name, img in (("clean", snap), ("lossy", lossy)):
        for combine in (False, True):
            est, reading = print_read.restore(*print_read.despread(img, 32, 4, combine=combine), 32, 4)
            err[name, combine] = (_rmse(est, planes), reading)
    assert err["lossy", True][0] < 0.85 * err["lossy", False][0]   # measured 0.79
    assert err["clean", True][0] <= 1.02 * err["clean", False][0]
    assert abs(err["lossy", True][1].gain / err["lossy", False][1].gain - 1) < 0.1
    for key in err:   # the pilots still predict the error without ground truth
        assert 0.6 < err[key][1].plane_rmse / err[key][0] < 1.6, key


def test_band_response_sees_what_a_copy_kept(embedded):
    """`band_response` (the bench's per-band measure, any band set via `make_layout`): a lossless copy keeps
    every band at gain 1; a copy that lost one band shows gain 0 there and 1 elsewhere."""
    host, planes, _ = embedded
    lay = print_carriers.make_layout(32, 4, {"Y2LH": 1.0, "RG2HL": 1.0, "YB3HH": 2.0})
    snap, _ = print_embed.embed_values(host, lay, print_embed.carrier_values(lay, planes))
    gain, noise = print_read.band_response(snap, snap, lay)
    assert np.allclose(gain, 1.0) and np.all(noise < 1e-12)
    coeffs = bands.analyse(snap / 255.0)
    coeffs["RG2HL"] = np.zeros_like(coeffs["RG2HL"])
    lossy = np.clip(np.round(bands.synthesise(coeffs) * 255), 0, 255).astype(np.uint8)
    gain, noise = print_read.band_response(lossy, snap, lay)
    assert abs(gain[1]) < 0.05 and np.all(np.abs(gain[[0, 2]] - 1) < 0.05), gain
    est = print_read.restore_layout(lay, *print_read.read_carriers(snap, lay))[0]
    assert _rmse(est, planes) < 0.5 * planes.std()   # any band set carries the planes
