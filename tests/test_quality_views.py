"""The print decode's scene-aware quality estimate (`viewer.quality_views`, issue 38 item 4): the expected
error spectrum, the views term, and the estimate against the measured restore on a scene held out of its
calibration."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.cameras import orbit_cameras
from snapshot3d.codecs.print_carriers import print_layout
from snapshot3d.codecs.print_read import VIEW_PRIOR
from snapshot3d.codecs.print_source import plane_dct, plane_idct, prior_spectrum
from snapshot3d.metrics import psnr
from snapshot3d.paths import asset
from snapshot3d.scene import load_scene_file
from snapshot3d.viewer.quality import VIEWS_PREDICTOR, load_calibration, quality_estimate
from snapshot3d.viewer.quality_views import (
    GAIN_SPREAD,
    ErrorSpectrum,
    ViewsCheck,
    error_draw,
    error_spectrum,
    fold_error,
    lost_signal,
    scene_power,
    views_psnr_expected,
)
from snapshot3d.viewer.render import render_views
from snapshot3d.viewer.runtime import field_models

SPOT = asset("spot-print.s3d")


def test_error_spectrum_has_the_readings_rmse_and_the_restores_shape():
    spec = error_spectrum(formats.PRINT_CODEC, 16, 4, gain=0.5, noise=1e-4, rmse=0.12)
    err = spec.total()
    assert err.shape == (3 * 4 * 16 * 16,) and np.all(err > 0)
    assert np.sqrt(err.mean()) == pytest.approx(0.12, rel=1e-9)
    quiet = error_spectrum(formats.PRINT_CODEC, 16, 4, gain=0.5, noise=1e-6, rmse=0.12).total()
    # a quieter channel leaves the carried (low) frequencies a smaller share of the error than the dropped ones
    lows = err.reshape(3, 4, 16, 16)[..., :2, :2].sum() / err.sum()
    assert quiet.reshape(3, 4, 16, 16)[..., :2, :2].sum() / quiet.sum() < lows
    # where a linear carrier alone holds a coefficient, noise let through plus signal shrunk away is the restore's
    # (weight w = a^2 k p / (a^2 k p + n), k = VIEW_PRIOR): (1 - w)^2 p + w^2 n / a^2, above the MMSE posterior
    # variance p n / (a^2 p + n) (the least a linear estimate leaves); the folded ones' is their unfold's, a fixed
    # share of the MMSE's below
    lay = print_layout(16, 4, formats.PRINT_CODEC)
    a2 = (lay.scale * 0.5) ** 2
    post = lay.prior * 1e-4 / (a2 * lay.prior + 1e-4)
    w = a2 * VIEW_PRIOR * lay.prior / (a2 * VIEW_PRIOR * lay.prior + 1e-4)
    lin = np.ones(len(lay.coef), bool)
    lin[lay.folded] = False
    mine = (err[lay.coef] / spec.scale)[lin]
    np.testing.assert_allclose(mine, ((1 - w) ** 2 * lay.prior + w * w * 1e-4 / a2)[lin], rtol=1e-9)
    assert VIEW_PRIOR > 1 and np.all(mine > post[lin] * (1 + 1e-9))
    np.testing.assert_allclose(spec.weight[lay.coef][lin], w[lin], rtol=1e-12)
    share = fold_error(lay, 0.5, 1e-4)
    assert 0 < share < 1
    np.testing.assert_allclose((err[lay.coef] / spec.scale)[lay.folded], share * post[lay.folded], rtol=1e-9)
    assert np.all((spec.weight[lay.coef] > 0) & (spec.weight[lay.coef] < 1))
    # the gain spread's error: w^2 GAIN_SPREAD / gain^2 on the linear carriers only
    np.testing.assert_allclose(spec.spread[lay.coef[lin]], spec.weight[lay.coef[lin]] ** 2 * GAIN_SPREAD / 0.25)
    assert np.all(spec.spread[lay.coef[lay.folded]] == 0) and spec.spread[spec.weight == 0].sum() == 0


def test_fold_error_falls_as_the_helix_reads_cleaner():
    """The folded coefficients' unfold error over their linear carrier's alone: well below 1 on a clean capture,
    higher where the helix's turns get confused, never above 1; repeatable."""
    lay = print_layout(24, 4, formats.PRINT_CODEC)
    clean, noisy = fold_error(lay, 1.0, 2e-4), fold_error(lay, 0.15, 2e-3)
    assert 0 < clean < 0.5 and clean < noisy <= 1.0, (clean, noisy)
    assert fold_error(lay, 1.0, 2e-4) == clean


def _restored_coefficients(spec: ErrorSpectrum, res: int, channels: int, rho: float, seed: int = 0) -> np.ndarray:
    """planes (3, C, R, R) whose carried DCT coefficients are what the restore of a scene with `rho` times the
    prior's power gives (E[r^2] = w^2 rho p + h w (1 - w) p, h the noise heard: `ErrorSpectrum.heard`), and 0
    where not carried."""
    p = np.tile(prior_spectrum(res).ravel(), 3 * channels)
    w = spec.weight
    r = np.sqrt(w * w * rho * p + spec.heard * w * (1 - w) * p) * np.random.default_rng(seed).standard_normal(p.size)
    return plane_idct(np.where(w > 0, r, 0.0), (3, channels, res, res)).astype(np.float32)


@pytest.mark.parametrize("rho", [0.5, 2.0])
def test_scene_power_reads_the_scenes_own_power_and_trusts_a_noisy_capture_less(rho):
    """24x4 planes (the codec drops their highest frequencies): a clean capture's carried coefficients say
    how far the scene's power is from the prior, and the estimate carries it to the dropped ones; a noisy
    capture's say little, and the estimate stays near the prior."""
    clean = error_spectrum(formats.PRINT_CODEC, 24, 4, gain=0.5, noise=1e-7, rmse=0.1)
    dropped = clean.weight == 0
    assert dropped.any()
    got = scene_power(_restored_coefficients(clean, 24, 4, rho), clean)
    assert got.shape == dropped.shape
    assert abs(10 * np.log10(np.median(got[dropped]) / rho)) < 1.0, np.median(got[dropped])
    noisy = error_spectrum(formats.PRINT_CODEC, 24, 4, gain=0.5, noise=3.0, rmse=0.3)
    assert np.median(noisy.weight[noisy.weight > 0]) < 0.2
    far = scene_power(_restored_coefficients(noisy, 24, 4, rho), noisy)
    assert abs(np.log(np.median(far[dropped]))) < abs(np.log(rho)) / 2, np.median(far[dropped])


def test_error_draw_puts_the_lost_signal_where_the_planes_have_detail():
    """The random draw (`coherent` False): the lost signal goes where the restored planes change (a square's
    edges), the channel noise evenly; a draw repeats with its seed."""
    res, ch = 32, 4
    planes = np.full((3, ch, res, res), -0.5, np.float32)
    planes[..., 8:24, 8:24] = 0.5
    gy, gx = np.gradient(planes[0, 0].astype(np.float64))
    edge = np.broadcast_to((gx * gx + gy * gy) > 0, planes.shape)
    spec = error_spectrum(formats.PRINT_CODEC, res, ch, gain=0.5, noise=1e-3, rmse=0.1)
    zero = np.zeros_like(spec.noise)
    lost_only = ErrorSpectrum(zero, spec.lost + spec.noise, spec.weight, spec.scale)
    noise_only = ErrorSpectrum(spec.noise + spec.lost, zero, spec.weight, spec.scale)
    rand = ViewsCheck(coherent=False)
    e = error_draw(planes, lost_only, rand)
    assert e.shape == planes.shape and e.dtype == np.float32
    assert np.mean(e[edge] ** 2) > 5 * np.mean(e[~edge] ** 2)
    n = error_draw(planes, noise_only, rand)
    assert 0.7 < np.mean(n[edge] ** 2) / np.mean(n[~edge] ** 2) < 1.4
    np.testing.assert_array_equal(error_draw(planes, lost_only, rand), e)
    assert not np.array_equal(error_draw(planes, lost_only, ViewsCheck(coherent=False, seed=1)), e)


def test_lost_signal_is_the_scenes_own_shrunk_and_its_edges_harmonics():
    """The coherent draw (shipped): where carried, the restored coefficients shrunk by (1 - w) once more (against
    their sign, of the size (1 - w) |x| read back from r); where dropped, a steepened copy's harmonics, at the
    square's edges, with the lost power of the dropped coefficients; no randomness (the seed moves the noise only)."""
    res, ch = 32, 4
    planes = np.full((3, ch, res, res), -0.5, np.float32)
    planes[..., 8:24, 8:24] = 0.5
    spec = error_spectrum(formats.PRINT_CODEC, res, ch, gain=0.5, noise=1e-3, rmse=0.1)
    rho = np.ones_like(spec.lost)
    got = lost_signal(planes, spec, rho, 3.0)
    r = plane_dct(planes)
    carried, w = spec.weight > 0, spec.weight
    assert np.all(got[carried] * r[carried] <= 0)          # shrinks: against the restored coefficient's sign
    heard = spec.heard * w * (1 - w) * np.tile(prior_spectrum(res).ravel(), 3 * ch)
    x2 = np.maximum(r * r - heard, 0) / np.maximum(w, 1e-3) ** 2
    np.testing.assert_allclose(got[carried] ** 2, ((1 - w) ** 2 * x2 * spec.scale)[carried], rtol=1e-9, atol=1e-15)
    assert np.sum(got[~carried] ** 2) == pytest.approx(np.sum(spec.lost[~carried]), rel=1e-9)
    dropped = plane_idct(np.where(carried, 0.0, got), planes.shape)
    gy, gx = np.gradient(planes[0, 0].astype(np.float64))
    near = np.broadcast_to(cv2.dilate(((gx * gx + gy * gy) > 0).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0,
                           planes.shape)
    assert np.mean(dropped[near] ** 2) > 5 * np.mean(dropped[~near] ** 2)
    lost_only = ErrorSpectrum(np.zeros_like(spec.noise), spec.lost, spec.weight, spec.scale)
    np.testing.assert_array_equal(error_draw(planes, lost_only), error_draw(planes, lost_only, ViewsCheck(seed=1)))


def test_gain_spread_adds_noise_in_proportion_to_the_scene():
    """The gain spread's error is random and grows with the scene's coefficients: planes of twice the contrast get
    about four times its power; none without it."""
    res, ch = 16, 4
    rng = np.random.default_rng(3)
    planes = (0.2 * rng.standard_normal((3, ch, res, res))).astype(np.float32)
    spec = error_spectrum(formats.PRINT_CODEC, res, ch, gain=0.5, noise=1e-4, rmse=0.05)
    bare = ErrorSpectrum(np.zeros_like(spec.noise), np.zeros_like(spec.lost), spec.weight, spec.scale)
    only = ErrorSpectrum(bare.noise, bare.lost, spec.weight, spec.scale, spec.spread)
    rand = ViewsCheck(coherent=False)   # no lost signal drawn: the gain spread's error alone
    assert not np.any(error_draw(planes, bare, rand))
    p1 = np.mean(error_draw(planes, only, rand) ** 2)
    p2 = np.mean(error_draw(2 * planes, only, rand) ** 2)
    assert p1 > 0 and 3.0 < p2 / p1 < 5.0, (p1, p2)


def test_views_term_falls_with_the_plane_error_and_repeats():
    scene = load_scene_file(SPOT)
    models, planes = field_models(decoder=scene.decoder_version), scene.planes()
    res, ch = planes.shape[2], planes.shape[1]
    got = [views_psnr_expected(models, planes, scene.box, scene.orbit,
                               error_spectrum(formats.PRINT_CODEC, res, ch, 0.5, 1e-4, rmse)) for rmse in (0.05, 0.15, 0.4)]
    assert got[0] > got[1] + 3 > got[2] + 6, got
    again = views_psnr_expected(models, planes, scene.box, scene.orbit,
                                error_spectrum(formats.PRINT_CODEC, res, ch, 0.5, 1e-4, 0.15))
    assert again == got[1]
    assert views_psnr_expected(models, planes, scene.box, scene.orbit,
                               error_spectrum(formats.PRINT_CODEC, res, ch, 0.5, 1e-4, 0.15), ViewsCheck(seed=1)) != got[1]
    with pytest.raises(ValueError, match="do not match"):
        views_psnr_expected(models, planes, scene.box, scene.orbit, error_spectrum(formats.PRINT_CODEC, 24, ch, 0.5, 1e-4, 0.15))


def test_shipped_print_calibration_reads_the_views_term():
    cal = load_calibration(formats.PRINT_CODEC)
    assert cal["predictor"] == VIEWS_PREDICTOR and (cal["slope"], cal["intercept"]) == (1.0, 0.0)
    # measured by `bench quality` (4 photos per host and physical severity, each digital capture once) on six
    # scenes of 16x4 to 48x4: issue 38's target, 1.5 dB on every scene, met (worst lego 16x4 1.38). Counting the
    # seed-independent jpeg90/jpeg75 captures once per seed had read 1.63-1.78 there; the log10 line shipped before
    # the views term read 5.1 dB on spot 48x4
    errors = {k: v["median_abs_error_db"] for k, v in cal["per_scene_held_out"].items()}
    assert len(errors) >= 6 and max(errors.values()) <= 1.5, errors
    assert cal["held_out_rmse_db"] <= 1.45, cal["held_out_rmse_db"]
    q = quality_estimate(formats.PRINT_CODEC, None, 0.12, 27.0)
    assert abs(q["restore_psnr_expected_db"] - (cal["intercept"] + cal["slope"] * 27.0)) < 0.01
    assert quality_estimate(formats.PRINT_CODEC, None, 0.12, None)["restore_psnr_expected_db"] is None


def test_estimate_holds_on_a_scene_held_out_of_its_calibration(tmp_path):
    """lego at 16x4 (the calibration saw spot 16x4 and lego 48x4): photos at mild and moderate, the estimate
    against the measured restore_psnr (the line ran 2.2 dB high here before the views term)."""
    from snapshot3d.bench.decode import _photo, _snapshot
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.qr import scene_meta
    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.viewer.decode import decode_photo

    scene = load_scene_file(Path(__file__).resolve().parents[1] / "bench/models/lego-print-auto.s3d")
    c2w, intr = orbit_cameras(scene.orbit, formats.ORBIT_VIEWS, 96)
    ref = render_views(field_models(decoder=scene.decoder_version), scene.planes(), scene.box, c2w, intr, 96, 96)
    sheet = render_sheet(_snapshot(scene, formats.PRINT_CODEC, load_host("builtin:coffee")),
                         scene_meta(scene, formats.PRINT_CODEC), 2)
    errors = []
    for sev in ("mild", "moderate"):
        dec = decode_photo(_photo(sheet, sev, 1000, tmp_path), size=96)
        errors.append(dec.report["quality_estimate"]["restore_psnr_expected_db"] - psnr(dec.views, ref))
        assert dec.report["timings_ms"]["quality"] > 0
    # measured -1.38 (mild) and -1.26 (moderate) with the coherent error draw (severe, not run here: +0.43); the
    # random draw before it -1.75 and -0.44; the log10 line shipped before that ran +1.3 and +2.1 dB here
    assert np.median(np.abs(errors)) <= 1.5 and max(abs(e) for e in errors) < 2.5, errors
