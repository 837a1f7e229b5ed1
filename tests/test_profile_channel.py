"""A channel profile drives `simulate` and the print budget (issue 38 item 3): a round trip calibrate ->
simulate --profile -> calibrate, the budget's choice through a profile measured on a `moderate` photo, and
one-line errors for profiles that are malformed or of another version."""
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli

from snapshot3d.scanner.calibrate import E2E_REFERENCE, PROFILE_VERSION, calibrate_image, load_profile
from snapshot3d.scanner.profile_channel import profile_channel, profile_preset, severity_position


@pytest.fixture(scope="module")
def moderate(tmp_path_factory):
    """The chart's sheet written by the CLI, a `moderate` photo of it and the profile calibrate writes."""
    d = tmp_path_factory.mktemp("profile")
    for args in (("sheet", "--calibration", "-o", str(d / "chart.pdf")),
                 ("simulate", str(d / "chart.pdf"), "-o", str(d / "a.jpg"), "--severity", "moderate", "--seed", "3"),
                 ("calibrate", str(d / "a.jpg"), "-o", str(d / "a.json"))):
        r = run_cli(*args)
        assert r.returncode == 0, r.stderr
    return d, load_profile(d / "a.json")


def test_simulate_profile_cli(moderate, tmp_path):
    """simulate --profile solves a preset from the profile (written into --truth) and its photo calibrates
    like the profile within the spread of one photo (the round trip's numbers: the slow test below)."""
    d, first = moderate
    r = run_cli("simulate", str(d / "chart.pdf"), "-o", str(tmp_path / "b.jpg"), "--profile", str(d / "a.json"),
                "--seed", "14", "--truth", str(tmp_path / "truth.json"))
    assert r.returncode == 0, r.stderr
    assert "profile a.json: moderate with defocus" in r.stdout
    truth = json.loads((tmp_path / "truth.json").read_text())
    solved = truth["profile"]
    assert solved["base"] == "moderate" and solved["clamped"] == [] and 0.5 < solved["defocus_px"] < 3.5
    assert abs(truth["sampled"]["defocus_px"] - solved["defocus_px"]) < 1e-3 and truth["sampled"]["motion_px"] == 0
    r = run_cli("calibrate", str(tmp_path / "b.jpg"), "-o", str(tmp_path / "b.json"))
    assert r.returncode == 0, r.stderr
    second = load_profile(tmp_path / "b.json")
    assert second["nearest_preset"] == "moderate"
    assert abs(np.log(second["mtf50"] / first["mtf50"])) < np.log(1.5), (first["mtf50"], second["mtf50"])
    assert abs(np.log(second["channel"]["gain"] / first["channel"]["gain"])) < np.log(1.5)


@pytest.mark.slow
def test_round_trip_median_of_three_photos():
    """calibrate(moderate photo, seeds 0-5) -> profile -> the solved preset, 3 photos of other seeds ->
    calibrate: their median MTF50 within 15 % and channel gain within 25 % of the profile in 6 of 6, the noise
    per coefficient within 25 % in 4 of 6: the counts measured (2026-11-26; the measure of 07:10 UTC), no
    margin. The two noise misses (+47 %, +84 %): profiles whose noise lies below what the preset reaches at
    its own sensor noise (the halftone's and paper's texture), and photos whose glare raises it (the light is
    drawn per photo); docs/calibration.md."""
    from snapshot3d.bench.calibrate import chart_capture

    logs = lambda p: np.log([p["mtf50"], p["channel"]["gain"], p["channel"]["unit"]])   # noqa: E731
    within = np.zeros(3, int)
    for seed in range(6):
        first = calibrate_image(chart_capture("moderate", seed)[0])
        preset, _ = profile_preset(first)
        second = [logs(calibrate_image(chart_capture(preset, seed + 20 + 7 * j)[0])) for j in range(3)]
        err = np.abs(np.median(second, 0) - logs(first))
        within += err < np.log([1.15, 1.25, 1.25])
    assert within[0] >= 6 and within[1] >= 6 and within[2] >= 4, within


def test_moderate_profile_gives_the_moderate_channel(moderate):
    """The channel a moderate photo's profile implies lies near the budget's `moderate` model (the photo's
    own spread: the chart's print_channel unit varies by a log std of about 0.3 between moderate photos) and
    between mild and severe on the severity axis."""
    from snapshot3d.train.field.curves import print_channel

    _, prof = moderate
    model, info = profile_channel(prof)
    ref = print_channel()
    assert 0.5 <= severity_position(prof) <= 1.5 and info["nearest_preset"] == "moderate"
    assert abs(np.log(model.gain / ref.gain)) < np.log(1.3), (model, ref)
    assert abs(np.log(model.unit / ref.unit)) < np.log(1.6), (model, ref)


@pytest.mark.slow
def test_budget_choice_on_a_moderate_profile(moderate):
    """The print ladder (spot's committed rungs, 5 held-out views) chooses the same rung through the profile's
    channel as through the `moderate` curve's, and spot 16x4's predicted e2e_psnr lies within 1.5 dB of the
    print benchmark's measured median at moderate (E2E_REFERENCE)."""
    from snapshot3d.loaders import load_scene
    from snapshot3d.paths import asset
    from snapshot3d.scene import dequantize_planes, load_scene_file
    from snapshot3d.train.field.budget import choose_rung, predicted_e2e
    from snapshot3d.train.field.curves import print_channel
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.evaluate import evaluate_planes

    _, prof = moderate
    model, _ = profile_channel(prof)
    posed = load_scene("builtin:spot", size=200)
    posed = replace(posed, test=posed.test[::4])
    decoder = load_decoder("tri-dec-1")
    root = Path(__file__).resolve().parents[1]
    files = [asset("spot-print.s3d")] + [root / "bench" / "models" / f"spot-r{r}c4.s3d" for r in (24, 48)]
    rungs = {"curve": [], "profile": []}
    for f in files:
        scene = load_scene_file(f)
        planes = dequantize_planes(scene.codes)
        field = evaluate_planes(planes, decoder, posed)["field_psnr"]
        for key, ch in (("curve", print_channel()), ("profile", model)):
            rungs[key].append({"scene_kb": scene.scene_kb, "field_psnr": field,
                               "e2e_expected": predicted_e2e(planes, decoder, posed, ch)})
    chosen = {key: choose_rung(r, 0.5, "e2e_expected") for key, r in rungs.items()}
    assert chosen["profile"] == chosen["curve"] == 0, rungs
    e2e = rungs["profile"][0]["e2e_expected"]
    assert abs(e2e - E2E_REFERENCE["moderate"][0]) < 1.5, (e2e, E2E_REFERENCE["moderate"])


def test_bad_profiles_are_one_line_errors(moderate, tmp_path):
    d, prof = moderate
    cases = {"other.json": json.dumps({**prof, "profile_version": PROFILE_VERSION + 1}),
             "text.json": "{ not json", "nounit.json": json.dumps({**prof, "channel": {"gain": 0.5}}),
             "zero.json": json.dumps({**prof, "mtf50": 0}),
             "nopc.json": json.dumps({k: v for k, v in prof.items() if k != "print_channel"})}
    expect = {"other.json": "version", "text.json": "not a channel profile", "nounit.json": "channel unit",
              "zero.json": "malformed", "nopc.json": "no print_channel"}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        if name != "nopc.json":   # simulate does not need the print channel
            r = run_cli("simulate", str(d / "chart.pdf"), "-o", str(tmp_path / "x.jpg"), "--profile",
                        str(tmp_path / name))
            assert_one_line_error(r, expect[name])
        r = run_cli("fit", "builtin:spot", "-o", str(tmp_path / "x.s3d"), "--budget", "auto", "--medium", "print",
                    "--channel", str(tmp_path / name))
        assert_one_line_error(r, expect[name])
    assert_one_line_error(run_cli("simulate", str(d / "chart.pdf"), "-o", str(tmp_path / "x.jpg"), "--profile",
                                  str(tmp_path / "missing.json")), "not found")
    r = run_cli("simulate", str(d / "chart.pdf"), "-o", str(tmp_path / "x.jpg"), "--profile", str(d / "a.json"),
                "--severity", "mild")
    assert_one_line_error(r, "not both")
    r = run_cli("fit", "builtin:spot", "-o", str(tmp_path / "x.s3d"), "--budget", "auto", "--channel",
                str(d / "a.json"))
    assert_one_line_error(r, "--medium print")
