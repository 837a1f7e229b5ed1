"""ONNX export of both models: checker-clean, pinned names and metadata, and parity with torch on
real inputs (an export failure fails here; it is never skipped)."""
import numpy as np
import onnx
import onnxruntime as ort
import torch

from snapshot3d import formats
from snapshot3d.export.models import ShadeGraph
from snapshot3d.export.onnx_export import OPSET, export_restore, export_shade
from snapshot3d.export.parity import restore_parity, shade_parity
from snapshot3d.train.codec import load_codec
from snapshot3d.train.decoder import load_decoder


def test_shade_graph_parity_random_inputs(tmp_path):
    path = tmp_path / "shade.onnx"
    export_shade(load_decoder(), path)
    model = onnx.load(str(path))
    meta = {p.key: p.value for p in model.metadata_props}
    assert meta["decoder_version"] == formats.DECODER_VERSION and meta["opset"] == str(OPSET)
    assert [i.name for i in model.graph.input] == ["planes", "points", "delta"]
    assert [o.name for o in model.graph.output] == ["rgb", "acc"]
    rng = np.random.default_rng(0)
    planes = rng.uniform(-1, 1, (3, formats.C_MAX, 40, 40)).astype(np.float32)  # another R than exported with
    pts = rng.uniform(-1, 1, (300, 7, 3)).astype(np.float32)
    delta = rng.uniform(0, 0.05, (300, 7)).astype(np.float32)
    rgb, acc = ort.InferenceSession(str(path)).run(None, {"planes": planes, "points": pts, "delta": delta})
    with torch.no_grad():
        trgb, tacc = ShadeGraph(load_decoder())(*(torch.from_numpy(a) for a in (planes, pts, delta)))
    assert np.abs(rgb - trgb.numpy()).max() < 1e-4 and np.abs(acc - tacc.numpy()).max() < 1e-4


def test_exported_models_match_torch_on_real_inputs(tmp_path):
    restore, shade = tmp_path / "restore.onnx", tmp_path / "shade.onnx"
    size = export_restore(load_codec()[0], restore)
    export_shade(load_decoder(), shade)
    assert size < 5e6
    meta = {p.key: p.value for p in onnx.load(str(restore)).metadata_props}
    assert meta["codec_id"] == formats.CODEC_ID and meta["orbit_views"] == str(formats.ORBIT_VIEWS)
    assert shade_parity(shade)["views_max_abs_diff"] <= 1e-3
    r = restore_parity(restore, shade)
    assert r["restore_psnr_diff_db"] <= 0.05 and r["restore_psnr_onnx"] > 20, r


def test_shipped_models_are_current(tmp_path):
    """The models inside the package were exported from the shipped weights (same outputs)."""
    from snapshot3d.viewer.runtime import model_path
    export_restore(load_codec()[0], tmp_path / "r.onnx")
    x = np.random.default_rng(1).uniform(0, 1, (1, 3, 380, 380)).astype(np.float32)
    a = ort.InferenceSession(str(model_path("restore"))).run(None, {"snapshot": x})[0]
    b = ort.InferenceSession(str(tmp_path / "r.onnx")).run(None, {"snapshot": x})[0]
    assert np.abs(a - b).max() < 1e-4
    export_shade(load_decoder(), tmp_path / "s.onnx")
    rng = np.random.default_rng(2)
    feeds = {"planes": rng.uniform(-1, 1, (3, formats.C_MAX, 32, 32)).astype(np.float32),
             "points": rng.uniform(-1, 1, (64, 5, 3)).astype(np.float32), "delta": np.full((64, 5), 0.03, np.float32)}
    for shipped, fresh in zip(ort.InferenceSession(str(model_path("shade"))).run(None, feeds),
                              ort.InferenceSession(str(tmp_path / "s.onnx")).run(None, feeds)):
        assert np.abs(shipped - fresh).max() < 1e-4
