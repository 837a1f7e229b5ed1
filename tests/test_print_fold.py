"""The print codec's folded carriers (`print-2`, `snapshot3d.codecs.print_fold`): the helix reads back exactly, the
strongest coefficients are the ones folded, the fold gains over the linear code `print-1` where the
capture's noise is low, and snapshots of either codec restore only with their own carriers."""
import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.codecs import print_carriers, print_embed, print_fold, print_read, print_source
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.qr import SheetMeta
from snapshot3d.viewer.media import restore_planes


def _rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


def test_unfold_reads_a_clean_helix_exactly_and_a_noisy_one_like_the_linear_carrier():
    rng = np.random.default_rng(0)
    x = np.clip(rng.standard_normal(500), -4, 4)
    cos, sin = print_fold.helix(x)
    tiny = np.full(500, 1e-10)
    est, var = print_fold.unfold(0.5 * x, np.full(500, 0.5), tiny, 2 * cos, 2 * sin, np.full(500, 2.0), tiny, tiny)
    assert np.abs(est - x).max() < 1e-3 and np.all(var < 1e-5)
    # helix drowned in noise: the posterior falls back on the linear reading's MMSE, not on a wrong turn
    lin = x + rng.normal(0, 0.5, 500)
    est, _ = print_fold.unfold(lin, np.ones(500), np.full(500, 0.25), rng.normal(0, 10, 500), rng.normal(0, 10, 500),
                               np.ones(500), np.full(500, 1e4), np.full(500, 1e4))
    assert np.allclose(est, lin / 1.25, atol=0.02)


def test_print2_folds_the_strongest_coefficients_and_print1_none():
    one, two = print_carriers.print_layout(16, 4, "print-1"), print_carriers.print_layout(16, 4, "print-2")
    assert len(one.folded) == 0 and one.carriers == print_carriers.PILOTS + len(one.coef)
    assert 250 <= len(two.folded) <= 350 and two.carriers == print_carriers.PILOTS + len(two.coef) + 2 * len(two.folded)
    assert len(np.unique(two.chips)) == two.chips.size
    power = (two.scale ** 2 * two.prior)
    power[two.folded] /= print_fold.FOLD_LINEAR
    rest = np.setdiff1d(np.arange(len(two.coef)), two.folded)
    assert power[two.folded].min() >= power[rest].max()
    with pytest.raises(ValueError, match="unknown print codec 'print-9'"):
        print_carriers.print_layout(16, 4, "print-9")


@pytest.fixture(scope="module")
def planes():
    return print_source.random_planes(16, 4, np.random.default_rng(2))


def _through_model(snap, codec, unit, seed):
    """A capture as `print_channel`'s model has it (gain 0.55, noise `unit` per unit relative noise)."""
    read, factor = print_read.despread(snap, 16, 4, combine=False, codec=codec)
    noisy = 0.55 * read + np.sqrt(unit * factor) * np.random.default_rng(seed).standard_normal(len(read))
    return print_read.restore(noisy, factor, 16, 4, codec=codec)


def test_folding_gains_where_the_capture_is_clean(planes):
    """Under the channel model at the noise of `mild` photos (unit 3), print-2's planes are closer than
    print-1's (3 draws each, same host and planes; measured about 0.6 dB); the pilots' error estimate still
    tracks the truth."""
    host = load_host("builtin:coffee")
    err = {}
    for codec in ("print-1", "print-2"):
        snap = print_embed.embed(host, planes, codec=codec)
        outs = [_through_model(snap, codec, 3.0, s) for s in range(3)]
        err[codec] = np.median([_rmse(est, planes) for est, _ in outs])
        for est, reading in outs:
            assert 0.6 < reading.plane_rmse / _rmse(est, planes) < 1.6
    assert err["print-2"] < 0.97 * err["print-1"], err


def test_each_print_codec_restores_with_its_own_carriers(planes):
    """A print-1 snapshot (made before print-2) still restores when its metadata names it; read as
    print-2 it does not: the codec id travels with the snapshot for a reason."""
    host = load_host("builtin:chelsea")
    snap = print_embed.embed(host, planes, codec="print-1")
    meta = SheetMeta(codec="print-1", planes=(16, 4))
    own, info = restore_planes(snap, meta)
    assert _rmse(own, planes) < 0.3 * planes.std() and info["plane_rmse_expected"] > 0
    wrong, _ = restore_planes(snap, SheetMeta(codec=formats.PRINT_CODEC, planes=(16, 4)))
    assert _rmse(wrong, planes) > 3 * _rmse(own, planes)
