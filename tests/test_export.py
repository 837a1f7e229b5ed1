"""ONNX export of the models: checker-clean, pinned names and metadata, and parity with torch on
real inputs (an export failure fails here; it is never skipped); the grid graphs against the
reference field maths; the print receiver's graph against its numpy reference, at every plane size and
for both print codecs."""
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from snapshot3d import formats
from snapshot3d.export.onnx_export import (
    OPSET,
    export_field,
    export_project,
    export_restore,
    export_restore_print,
)
from snapshot3d.export.parity import (
    field_parity,
    print_graph_agrees,
    print_parity,
    restore_parity,
    torch_field_models,
)
from snapshot3d.head import encode_head
from snapshot3d.train.codec.hinet import load_codec
from snapshot3d.train.field.decoder import load_decoder
from snapshot3d.train.field.field import decode, sample_planes
from snapshot3d.train.field.head import with_head
from snapshot3d.viewer.bake import cell_coords, grid_field
from snapshot3d.viewer.runtime import FieldModels, own_head


def _export_field_models(tmp_path, version=formats.DECODER_VERSION):
    dec = load_decoder(version)
    export_project(dec, tmp_path / f"project-{version}.onnx", version)
    export_field(dec, tmp_path / f"field-{version}.onnx", version)
    return tmp_path / f"project-{version}.onnx", tmp_path / f"field-{version}.onnx"


@pytest.mark.parametrize("version", formats.DECODERS)
def test_grid_field_graphs_match_the_reference_field(tmp_path, version):
    """project + field (ORT, and their torch graphs) at grid cells == sample_planes + decode at the
    cells' centres, for another R and grid size than exported with, for every decoder version this build reads."""
    project, field = _export_field_models(tmp_path, version)
    for path, names_in, names_out in ((project, ["planes", "interp"], ["tables"]),
                                      (field, ["tables", "rows"], ["density_logit", "rgb", "hidden"])):
        model = onnx.load(str(path))
        meta = {p.key: p.value for p in model.metadata_props}
        assert meta["decoder_version"] == version and meta["opset"] == str(OPSET)
        assert [i.name for i in model.graph.input] == names_in and [o.name for o in model.graph.output] == names_out
    rng = np.random.default_rng(0)
    planes = rng.uniform(-1, 1, (3, formats.C_MAX, 40, 40)).astype(np.float32)
    res = 24
    cells = rng.integers(0, res, (500, 3))
    c = cell_coords(res)
    with torch.no_grad():
        sigma, rgb = decode(sample_planes(torch.from_numpy(planes), torch.from_numpy(c[cells])), load_decoder(version))
    want = torch.log(sigma).numpy(), rgb.numpy()
    for models in (FieldModels(ort.InferenceSession(str(project)), ort.InferenceSession(str(field))),
                   torch_field_models(version)):
        logit, got_rgb = grid_field(models, planes, res, cells)
        assert np.allclose(np.minimum(logit, formats.DENSITY_CLAMP), want[0], rtol=1e-5, atol=1e-4)  # logits reach 40
        assert np.abs(got_rgb - want[1]).max() < 1e-4
    # a scene's own head (snapshot3d.head): the runtime's numpy head on the graph's hidden output == the torch
    # decoder with that last layer
    dec = load_decoder(version)
    text = encode_head(rng.normal(0, 0.05, (4, dec.hidden + 1)))
    with torch.no_grad():
        sigma, rgb = decode(sample_planes(torch.from_numpy(planes), torch.from_numpy(c[cells])), with_head(dec, text))
    want_head = torch.log(sigma).numpy(), rgb.numpy()
    assert np.abs(want_head[1] - want[1]).max() > 1e-2   # the head changes the field
    own, tm = own_head(version, text), torch_field_models(version)
    for models in (FieldModels(ort.InferenceSession(str(project)), ort.InferenceSession(str(field)), own),
                   FieldModels(tm.project, tm.field, own)):
        logit, got_rgb = grid_field(models, planes, res, cells)
        assert np.allclose(np.minimum(logit, formats.DENSITY_CLAMP), want_head[0], rtol=1e-5, atol=1e-4)
        assert np.abs(got_rgb - want_head[1]).max() < 1e-4


def test_exported_models_match_torch_on_real_inputs(tmp_path):
    restore = tmp_path / "restore.onnx"
    size = export_restore(load_codec()[0], restore)
    project, field = _export_field_models(tmp_path)
    assert size < 5e6
    meta = {p.key: p.value for p in onnx.load(str(restore)).metadata_props}
    assert meta["codec_id"] == formats.FILE_CODEC and meta["orbit_views"] == str(formats.ORBIT_VIEWS)
    assert field_parity(project, field)["views_max_abs_diff"] <= 1e-3
    r = restore_parity(restore)
    assert r["restore_psnr_diff_db"] <= 0.05 and r["restore_psnr_onnx"] > 20, r


def test_print_graph_matches_the_numpy_receiver_on_real_captures(tmp_path):
    """restore-print.onnx reads a lossless print snapshot and the scan of a moderate photo of its sheet as the
    numpy receiver does (the same 8-bit planes, the same views), for both print codecs."""
    graph = tmp_path / "restore-print.onnx"
    assert export_restore_print(graph) < 5e6
    meta = {p.key: p.value for p in onnx.load(str(graph)).metadata_props}
    assert meta["codec_id"].split(",") == list(formats.PRINT_CODECS)
    rows = print_parity(graph)
    assert sorted(rows) == sorted(f"{c} {k}" for c in formats.PRINT_CODECS for k in ("lossless", "moderate"))
    for name, row in rows.items():
        assert print_graph_agrees(row), (name, row)
        assert row["restore_psnr_onnx"] > (40 if "lossless" in name else 18), (name, row)


def test_print_graph_reads_every_plane_size_and_codec(tmp_path):
    """One graph, any layout: planes of other sizes than it was traced with, and print-1's layout (no folded
    carriers), read from a noisy snapshot as numpy reads them."""
    from snapshot3d.codecs import print_embed, print_feeds, print_read, print_source
    from snapshot3d.scanner.backgrounds import load_host
    graph = tmp_path / "restore-print.onnx"
    export_restore_print(graph)
    sess = ort.InferenceSession(str(graph), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(3)
    host = load_host("builtin:chelsea")
    for (r, c), codec in (((24, 4), "print-2"), ((48, 2), "print-2"), ((16, 4), "print-1")):
        planes = print_source.random_planes(r, c, rng)
        snap = print_embed.embed(host, planes, codec=codec)
        noisy = np.clip(snap + rng.normal(0, 4, snap.shape), 0, 255).astype(np.uint8)
        want, reading = print_read.restore(*print_read.despread(noisy, r, c, codec=codec), r, c, codec=codec)
        got, got_reading = sess.run(None, print_feeds.graph_feeds(noisy, r, c, codec))
        assert got.shape == (3, c, r, r) and np.abs(got - want).max() < 1e-4, (r, c, codec)
        assert np.allclose(got_reading, [reading.gain, reading.noise, reading.plane_rmse], rtol=1e-4)


def test_print_graph_rejects_a_degenerate_band_combination_as_numpy_does():
    """A severe photo (lego 48x4 in rocket, the decode bench's seed 1000) whose pilots make the combined filters
    blow up to 1e22: numpy's float64 check rejects them; the float32 graph once took them (inf / inf) and
    restored NaN planes. It must read the photo as numpy does."""
    from snapshot3d.codecs import print_embed, print_feeds, print_read
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.qr import scene_meta
    from snapshot3d.scanner.roundtrip import capture
    from snapshot3d.scene import load_scene_file
    from snapshot3d.viewer.runtime import model_path
    scene = load_scene_file(Path(__file__).parents[1] / "bench" / "models" / "lego-print.s3d")
    snap = print_embed.embed(load_host("builtin:rocket"), scene.planes())
    cap = capture(snap, scene_meta(scene, "print-2"), "severe", 1000)
    r, c = scene.resolution, scene.channels
    want, reading = print_read.restore(*print_read.despread(cap, r, c), r, c)
    got, got_reading = ort.InferenceSession(str(model_path("restore-print"))).run(None, print_feeds.graph_feeds(cap, r, c))
    assert np.isfinite(got).all() and np.abs(got - want).max() < 1e-4
    assert np.allclose(got_reading, [reading.gain, reading.noise, reading.plane_rmse], rtol=1e-4)


def test_shipped_models_are_current(tmp_path):
    """The models inside the package were exported from the shipped weights (same outputs), the restore graph
    of every file codec this build reads (older snapshots name older codecs) as well as the current one's."""
    from snapshot3d.train.codec.hinet import codec_path
    from snapshot3d.viewer.runtime import model_path
    x = np.random.default_rng(1).uniform(0, 1, (1, 3, 380, 380)).astype(np.float32)
    assert formats.FILE_CODEC in formats.FILE_CODECS
    for codec in formats.FILE_CODECS:
        export_restore(load_codec(codec_path(codec))[0], tmp_path / "r.onnx", codec)
        shipped = str(model_path("restore", codec))
        assert {p.key: p.value for p in onnx.load(shipped).metadata_props}["codec_id"] == codec
        a = ort.InferenceSession(shipped).run(None, {"snapshot": x})[0]
        b = ort.InferenceSession(str(tmp_path / "r.onnx")).run(None, {"snapshot": x})[0]
        assert np.abs(a - b).max() < 1e-4, codec
    project, field = _export_field_models(tmp_path)
    rng = np.random.default_rng(2)
    planes = rng.uniform(-1, 1, (3, formats.C_MAX, 32, 32)).astype(np.float32)
    cells = rng.integers(0, 16, (64, 3))
    shipped = FieldModels(ort.InferenceSession(str(model_path("project"))), ort.InferenceSession(str(model_path("field"))))
    fresh = FieldModels(ort.InferenceSession(str(project)), ort.InferenceSession(str(field)))
    for x, y in zip(grid_field(shipped, planes, 16, cells), grid_field(fresh, planes, 16, cells)):
        assert np.abs(x - y).max() < 1e-4
    from snapshot3d.codecs import print_feeds
    export_restore_print(tmp_path / "p.onnx")
    feeds = print_feeds.graph_feeds((rng.uniform(0, 255, (380, 380, 3))).astype(np.uint8), 16, 4)
    a = ort.InferenceSession(str(model_path("restore-print"))).run(None, feeds)
    b = ort.InferenceSession(str(tmp_path / "p.onnx")).run(None, feeds)
    assert all(np.abs(x - y).max() < 1e-5 for x, y in zip(a, b))


def test_export_writes_the_restore_graph_of_every_file_codec():
    """`export` remakes the graphs of older codecs too (snapshots that name them still restore), each with its
    parity checked: the shipped export.json lists them all."""
    import json

    from snapshot3d.export.onnx_export import restore_keys
    from snapshot3d.paths import asset, model_file
    keys = restore_keys()
    assert sorted(keys.values()) == sorted(formats.FILE_CODECS) and keys["restore"] == formats.FILE_CODEC
    doc = json.loads(asset("export.json").read_text())
    for key, codec in keys.items():
        assert doc["models"][key]["path"] == model_file("restore", codec)
        assert doc["parity"][key]["restore_psnr_diff_db"] <= 0.05
