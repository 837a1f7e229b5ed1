"""The print channel's model (`snapshot3d.codecs.print_channel`): measured from a real simulated capture, it
predicts that capture's plane error; its limits behave (no noise: the digital restore; more noise: worse);
the ladder's codec share inverts the e2e sum; the shipped constants are sane."""
import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.codecs import print_embed, print_read
from snapshot3d.codecs.print_channel import ChannelModel, measure, predicted_planes
from snapshot3d.paths import asset
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import load_scene_file
from snapshot3d.train.field.budget import codec_share, expected_e2e, print_channel


def _rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


@pytest.fixture(scope="module")
def captured():
    from snapshot3d.scanner.roundtrip import capture

    scene = load_scene_file(asset("spot-print.s3d"))
    host = load_host("builtin:chelsea")
    snap = print_embed.embed(host, scene.planes())
    cap = capture(snap, scene_meta(scene, formats.PRINT_CODEC), "moderate", 1, sheet_dots=4)
    return scene, host, snap, cap


def test_model_measured_on_a_capture_predicts_its_error(captured):
    scene, host, snap, cap = captured
    r, c = scene.resolution, scene.channels
    ch = measure(snap, cap, r, c)
    assert 0.1 < ch.gain < 2 and ch.unit > 0
    truth = scene.planes()
    measured = _rmse(print_read.restore(*print_read.despread(cap, r, c, combine=False), r, c)[0], truth)   # the receiver it models
    rng = np.random.default_rng(0)
    predicted = np.median([_rmse(predicted_planes(host, truth, ch, rng), truth) for _ in range(4)])
    assert predicted == pytest.approx(measured, rel=0.25), (predicted, measured)


def test_model_limits(captured):
    scene, host, _, _ = captured
    r, c = scene.resolution, scene.channels
    truth, rng = scene.planes(), np.random.default_rng(1)
    digital = _rmse(print_read.restore(*print_read.despread(print_embed.embed(host, truth), r, c, combine=False), r, c)[0], truth)   # as the model reads it
    clean = _rmse(predicted_planes(host, truth, ChannelModel(1.0, 1e-12), rng), truth)
    assert clean == pytest.approx(digital, rel=0.02)
    errors = [_rmse(predicted_planes(host, truth, ChannelModel(0.5, u), rng), truth) for u in (1.0, 10.0, 100.0)]
    assert errors[0] < errors[1] < errors[2]


def test_codec_share_inverts_the_e2e_sum():
    for field, codec in ((30.0, 25.0), (27.6, 26.0), (35.0, 18.0)):
        assert codec_share(field, expected_e2e(field, codec)) == pytest.approx(codec, abs=1e-6)
    assert codec_share(30.0, 30.0) == 99.0


def test_shipped_channel_constants():
    ch = print_channel()
    assert ch is not None, "budget-curves.json has no print channel: run 'snapshot3d bench print-predict'"
    assert 0.1 < ch.gain < 2 and 0.1 < ch.unit < 1000


def test_writing_a_payload_curve_keeps_the_channel_model(tmp_path, monkeypatch):
    import json

    import snapshot3d.paths
    from snapshot3d.bench.common import update_budget_curve

    path = tmp_path / "budget-curves.json"
    path.write_text(json.dumps({"print": {"points": [[1, 2.0]], "channel": {"gain": 0.5, "unit": 12.0}}}))
    monkeypatch.setattr(snapshot3d.paths, "asset", lambda name: path)
    update_budget_curve("print", [(3072, 25.0)], "moderate", "a test")
    got = json.loads(path.read_text())["print"]
    assert got["points"] == [[3072, 25.0]] and got["channel"] == {"gain": 0.5, "unit": 12.0}


def test_a_photo_whose_band_combination_misreads_carriers_restores_finite_planes(tmp_path):
    """A `severe` photo (spot-print in rocket, seed 1002) whose pilots' band combination reads a few carriers with
    the wrong sign: those keep their designed filters, so no carrier's noise overflows float32. Before, the
    graph's planes held 256 NaN and its expected rmse was NaN (numpy's noise factor reached 4e54)."""
    from snapshot3d.bench.decode import _photo, _snapshot
    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.viewer.decode import read_input
    from snapshot3d.viewer.media import restore_print

    scene = load_scene_file(asset("spot-print.s3d"))
    sheet = render_sheet(_snapshot(scene, formats.PRINT_CODEC, load_host("builtin:rocket")),
                         scene_meta(scene, formats.PRINT_CODEC), 2)
    _, capture, meta, _ = read_input(_photo(sheet, "severe", 1002, tmp_path))
    read, factor = print_read.despread(capture, *meta.planes, codec=meta.codec)
    assert np.all(np.isfinite(factor)) and factor.max() < 1.0
    mine, reading = print_read.restore(read, factor, *meta.planes, codec=meta.codec)
    graph, greading = restore_print(capture, *meta.planes, None, meta.codec)
    assert np.all(np.isfinite(mine)) and np.all(np.isfinite(graph)) and np.isfinite(greading.plane_rmse)
    np.testing.assert_allclose(graph, mine, rtol=1e-3, atol=1e-3)
    assert greading.plane_rmse == pytest.approx(reading.plane_rmse, rel=1e-3, abs=1e-5)
