"""The calibration chart and `snapshot3d calibrate` (issue 38 items 1-2): round trips through each physical
preset, photos without the chart, the chart refused by decode, and channel profiles of another version."""
import json

import cv2
import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli

from snapshot3d.errors import UserError
from snapshot3d.scanner.calibrate import PROFILE_VERSION, calibrate_image, load_profile
from snapshot3d.scanner.chart import chart_snapshot
from snapshot3d.scanner.chart_measure import measure_chart
from snapshot3d.scanner.sheet import chart_sheet


@pytest.fixture(scope="module")
def chart_photo(tmp_path_factory):
    """A lossless photo (severity none) of the chart's sheet written by the CLI, and its folder."""
    d = tmp_path_factory.mktemp("chart")
    r = run_cli("sheet", "--calibration", "-o", str(d / "chart.pdf"))
    assert r.returncode == 0, r.stderr
    assert (d / "chart.pdf").read_bytes()[:5] == b"%PDF-" and (d / "chart.png").is_file()
    r = run_cli("simulate", str(d / "chart.pdf"), "-o", str(d / "photo.png"), "--severity", "none")
    assert r.returncode == 0, r.stderr
    return d


def test_chart_is_deterministic_and_measures_itself_exactly():
    a, b = chart_snapshot(), chart_snapshot()
    assert a.shape == (380, 380, 3) and a.dtype == np.uint8 and np.array_equal(a, b)
    m = measure_chart(np.array(a))
    assert m["noise_std"] < 1e-6 and m["colour_rmse"] == 0 and m["misregistration_px"] < 0.01
    assert all(abs(v["gain"] - 1) < 1e-6 and v["noise"] < 1e-12 for v in m["bands"].values())
    assert 0.5 < m["mtf50"] < 0.65   # an ideal edge sampled by square pixels: MTF50 about 0.58 cycles per pixel
    sheet = chart_sheet(2)
    assert sheet.shape[2] == 3 and sheet.std() > 20


@pytest.mark.parametrize("severity", ["mild", "moderate", "severe"])
def test_round_trip_each_preset(severity):
    """calibrate names the preset a simulated photo came through, and its MTF50 is the simulator's own: what
    the same seed reads without sensor noise and JPEG loss (bench.calibrate.reference_mtf50; the bench's 18
    photos lie within 2 %)."""
    from snapshot3d.bench.calibrate import chart_capture, reference_mtf50

    for seed in (0, 1):
        img, truth = chart_capture(severity, seed)
        prof = calibrate_image(img)
        assert prof["nearest_preset"] == severity, (seed, prof["preset_distance"])
        assert prof["profile_version"] == PROFILE_VERSION
        assert set(prof["bands"]) >= {"Y2LH", "Y1LH", "RG2LH"} and 0.05 < prof["channel"]["gain"] < 1.1
        sim = reference_mtf50(severity, seed)
        assert abs(prof["mtf50"] / sim - 1) < 0.08, (seed, prof["mtf50"], sim)
        assert {"mild": 0.30, "moderate": 0.22, "severe": 0.15}[severity] < prof["mtf50"] < 0.6


def test_mtf_follows_a_known_blur():
    """The MTF measure itself: the chart's sheet blurred in photo space by Gaussians of sigma s1 and s2
    (linear light, 3 photo pixels per snapshot pixel); the s2 photo's MTF50 is what the s1 photo's mean MTF
    curve times the Gaussian of the difference (in snapshot pixels, through the scan's scale) predicts
    (measured: within 3 %)."""
    from snapshot3d.scanner import chart
    from snapshot3d.scanner.calibrate import photo_linear
    from snapshot3d.scanner.chart_measure import edge_mtf, mtf50
    from snapshot3d.scanner.rectify import photo_px_per_unit
    from snapshot3d.scanner.scan import scan_image

    lin = (chart_sheet(3, caption=False).astype(np.float32) / 255.0) ** 2.2

    def curve(sigma):
        img = np.clip(cv2.GaussianBlur(lin, (0, 0), sigma) ** (1 / 2.2) * 255 + 0.5, 0, 255).astype(np.uint8)
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
        res = scan_image(img, chart=True)
        lum = photo_linear(img, res.fit) @ np.array([0.2126, 0.7152, 0.0722])
        curves = [edge_mtf(lum[y0:y1, x0:x1], v) for x0, y0, x1, y1, v in chart.EDGE_ROIS]
        return curves[0][0], np.mean([m for _, m in curves], 0), photo_px_per_unit(res.fit)

    for s1, s2 in ((1.0, 2.0), (0.8, 1.6)):
        f, m1, scale = curve(s1)
        _, m2, _ = curve(s2)
        pred = mtf50(f, m1 * np.exp(-2 * (np.pi * f) ** 2 * (s2 ** 2 - s1 ** 2) / scale ** 2))
        assert abs(mtf50(f, m2) / pred - 1) < 0.08, (s1, s2, mtf50(f, m2), pred)
        assert pred < 0.9 * mtf50(f, m1)   # the blur's difference is large enough to test something


@pytest.mark.parametrize("severity", ["mild", "moderate", "severe"])
def test_band_gain_and_noise_match_the_codecs_carriers(severity):
    """Per band, the chart's gain and noise (print_channel's terms) are what the print codec's own carriers
    read at the chart's places through the same seed (bench.calibrate.codec_reference, over 3 draws of the
    planes): the gain within 10 % of the expected reading (each square's gain weighed as the codec's filters
    weigh it), each square's gain within 10 %, noise within 25 % (severe 35 %)."""
    from snapshot3d.bench.calibrate import chart_capture, codec_reference

    seed = 2
    prof = calibrate_image(chart_capture(severity, seed)[0])
    ref = codec_reference(severity, seed, np.random.default_rng(0))
    u_tol = {"severe": 0.35}.get(severity, 0.25)
    for b, g in ref["expected"]["band_gain"].items():
        got = prof["bands"][b]
        assert abs(got["gain"] / g - 1) <= 0.10, (b, got["gain"], g)
        for mine, theirs in zip(got["squares"], ref["expected"]["squares"][b]):
            assert abs(mine / theirs - 1) <= 0.10, (b, got["squares"], ref["expected"]["squares"][b])
        unit = ref["places"]["band_unit"][b]
        assert abs(got["unit"] / unit - 1) <= u_tol, (b, got["unit"], unit)
    assert abs(prof["print_channel"]["unit"] / ref["places"]["unit"] - 1) <= u_tol
    assert set(prof["print_channel"]) == {"gain", "unit"} and 0 < prof["print_channel"]["gain"] < 1


def test_chart_of_another_version_is_refused(tmp_path):
    """A calib-1 chart (+-1 carriers, read by no build since calib-2) gets one line saying to print a new one."""
    from snapshot3d.scanner.qr import SheetMeta
    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.scanner.simulate import simulate

    assert chart_snapshot()[194:378, 6:190].std() == pytest.approx(20.4, abs=0.5)   # Gaussian carriers, std 0.08
    sheet = render_sheet(chart_snapshot(), SheetMeta(codec="calib-1"), 2)
    data, ext, _ = simulate(sheet, "none", 0)
    with pytest.raises(UserError, match="another version") as e:
        calibrate_image(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))
    assert "\n" not in str(e.value) and "calib-2" in str(e.value)


def test_calibrate_cli_writes_a_profile_that_loads(chart_photo, tmp_path):
    out, rep = tmp_path / "profile.json", tmp_path / "report.json"
    r = run_cli("calibrate", str(chart_photo / "photo.png"), "-o", str(out), "--report", str(rep))
    assert r.returncode == 0, r.stderr
    assert "nearest preset: mild" in r.stdout and "MTF50" in r.stdout and len(r.stdout.splitlines()) <= 20
    prof = load_profile(out)
    assert prof["mtf50"] > 0.4 and prof["channel"]["gain"] > 0.8 and prof["noise_std"] < 1.0
    assert json.loads(rep.read_text())["timings_ms"]["scan"] > 0


def test_profile_of_another_version_or_malformed(tmp_path, chart_photo):
    good = tmp_path / "good.json"
    assert run_cli("calibrate", str(chart_photo / "photo.png"), "-o", str(good)).returncode == 0
    data = json.loads(good.read_text())
    assert data["print_channel"]["unit"] > 0 and all("unit" in v for v in data["bands"].values())
    old = {k: v for k, v in data.items() if k != "print_channel"}   # a profile from before print_channel loads
    (tmp_path / "old.json").write_text(json.dumps(old))
    assert "print_channel" not in load_profile(tmp_path / "old.json")
    cases = {"other.json": json.dumps({**data, "profile_version": PROFILE_VERSION + 1}),
             "text.json": "not json {", "list.json": "[1, 2]", "nofield.json": json.dumps({"profile_version": PROFILE_VERSION}),
             "nan.json": json.dumps({**data, "mtf50": float("nan")}),
             "preset.json": json.dumps({**data, "nearest_preset": "awful"}),
             "pc.json": json.dumps({**data, "print_channel": {"gain": 0.5, "unit": -1.0}})}
    expect = {"other.json": "version", "text.json": "not a channel profile", "list.json": "no profile_version",
              "nofield.json": "malformed", "nan.json": "malformed", "preset.json": "unknown preset",
              "pc.json": "malformed"}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(UserError, match=expect[name]) as e:
            load_profile(tmp_path / name)
        assert "\n" not in str(e.value)
    with pytest.raises(UserError, match="not found"):
        load_profile(tmp_path / "missing.json")


def test_photo_without_the_chart(tmp_path):
    from snapshot3d.scanner.backgrounds import background_names, load_background

    rng = np.random.default_rng(0)
    wall = cv2.resize(load_background(background_names()[0]), (1600, 1200), interpolation=cv2.INTER_CUBIC)
    cv2.imwrite(str(tmp_path / "wall.jpg"), cv2.cvtColor(wall, cv2.COLOR_RGB2BGR))
    assert_one_line_error(run_cli("calibrate", str(tmp_path / "wall.jpg")), "no snapshot3d sheet found")
    # a snapshot's sheet is a sheet, but not the chart
    from snapshot3d.scanner.qr import SheetMeta
    from snapshot3d.scanner.sheet import render_sheet

    snap = rng.integers(0, 255, (380, 380, 3), np.uint8)
    sheet = render_sheet(snap, SheetMeta(codec="print-2"), 2)
    cv2.imwrite(str(tmp_path / "sheet.png"), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    assert_one_line_error(run_cli("calibrate", str(tmp_path / "sheet.png")), "not the calibration chart")


def test_decode_and_scan_refuse_the_chart(chart_photo, tmp_path):
    r = run_cli("decode", str(chart_photo / "photo.png"), "-o", str(tmp_path / "scene"))
    assert_one_line_error(r, "snapshot3d calibrate")
    r = run_cli("scan", str(chart_photo / "photo.png"), "-o", str(tmp_path / "snap.png"))
    assert_one_line_error(r, "calibration chart")


def test_sheet_calibration_options(tmp_path):
    assert_one_line_error(run_cli("sheet", "-o", str(tmp_path / "s.pdf")), "give the snapshot")
    r = run_cli("sheet", str(tmp_path / "x.png"), "--calibration", "-o", str(tmp_path / "s.pdf"))
    assert_one_line_error(r, "--calibration writes the calibration chart")
    assert_one_line_error(run_cli("calibrate", "nothing.jpg", "-o", str(tmp_path / "p.txt")), ".json")


def test_bench_refuses_counts_below_one():
    """`bench calibrate` with no photos or no draws of the reference's planes says so in one line."""
    for opt in ("--seeds", "--draws"):
        assert_one_line_error(run_cli("bench", "calibrate", "--pilots", opt, "0", "--out", "/nonexistent/x"),
                              f"{opt} must be at least 1")
