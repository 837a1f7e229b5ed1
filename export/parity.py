"""torch (for the print receiver, its numpy reference) against onnxruntime on real inputs (the shipped spot
scenes, a real host, a simulated photo): the checks the export command reports and the tests assert."""
from __future__ import annotations

import numpy as np
import torch

from snapshot3d import formats

__all__ = ["TorchRun", "torch_field_models", "field_parity", "restore_parity", "print_parity", "print_graph_agrees"]


def _spot():
    from snapshot3d.paths import asset
    from snapshot3d.scene import load_scene_file
    return load_scene_file(asset("spot.s3d"))


class TorchRun:
    """An onnxruntime session's `run`, computed by the torch graph it was exported from."""

    def __init__(self, graph, inputs, outputs):
        self.graph, self.inputs, self.outputs = graph.eval(), inputs, outputs

    def run(self, names, feeds):
        with torch.no_grad():
            out = self.graph(*(torch.from_numpy(np.asarray(feeds[k])) for k in self.inputs))
        got = dict(zip(self.outputs, (t.numpy() for t in (out if isinstance(out, tuple) else (out,)))))
        return [got[k] for k in (names or self.outputs)]


def torch_field_models(decoder: str = formats.DECODER_VERSION):
    """`viewer.runtime.FieldModels` computed by torch from the shipped decoder of version `decoder`."""
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.viewer.runtime import FieldModels

    from .models import FIELD_INPUTS, FIELD_OUTPUTS, PROJECT_INPUTS, PROJECT_OUTPUTS, FieldGraph, ProjectGraph

    dec = load_decoder(decoder)
    return FieldModels(TorchRun(ProjectGraph(dec), PROJECT_INPUTS, PROJECT_OUTPUTS),
                       TorchRun(FieldGraph(dec), FIELD_INPUTS, FIELD_OUTPUTS))


def _ort_field_models(project_path, field_path):
    from snapshot3d.viewer.runtime import FieldModels, session
    return FieldModels(session(str(project_path)), session(str(field_path)))


def field_parity(project_path, field_path, size: int = 96, decoder: str = formats.DECODER_VERSION) -> dict:
    """Max abs difference of the views of spot's planes rendered through the ORT graphs of decoder version
    `decoder` and through torch (the same renderer around them)."""
    from snapshot3d.cameras import orbit_cameras
    from snapshot3d.viewer.render import render_views

    scene = _spot()
    c2w, intr = orbit_cameras(scene.orbit, 3, size)
    ort_views = render_views(_ort_field_models(project_path, field_path), scene.planes(), scene.box, c2w, intr,
                             size, size)
    torch_views = render_views(torch_field_models(decoder), scene.planes(), scene.box, c2w, intr, size, size)
    return {"views_max_abs_diff": float(np.abs(ort_views - torch_views).max())}


def restore_parity(restore_path, size: int = 96, codec: str = formats.FILE_CODEC) -> dict:
    """restore_psnr of spot hidden in a bundled host by file codec `codec`, restored by its torch network and by
    the ORT graph at `restore_path` (the same renderer: the shipped graphs of the scene's decoder)."""
    from snapshot3d.cameras import orbit_cameras
    from snapshot3d.codecs import file_layout
    from snapshot3d.images import snapshot_nchw
    from snapshot3d.metrics import psnr
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scene import dequantize_planes, quantize_planes
    from snapshot3d.train.codec.hinet import codec_path, embed_planes, load_codec, restore_secret
    from snapshot3d.viewer.render import render_views
    from snapshot3d.viewer.runtime import scene_models, session

    scene = _spot()
    net, _ = load_codec(codec_path(codec))
    snap = embed_planes(net, load_host("builtin:coffee"), scene.planes())
    sec_torch = restore_secret(net, snap)
    sec_ort = session(str(restore_path)).run(None, {"snapshot": snapshot_nchw(snap)})[0][0]
    c2w, intr = orbit_cameras(scene.orbit, formats.ORBIT_VIEWS, size)
    models = scene_models(scene)
    ref = render_views(models, scene.planes(), scene.box, c2w, intr, size, size)

    def score(secret):
        planes = file_layout.secret_to_planes(secret, scene.resolution, scene.channels)
        return psnr(render_views(models, dequantize_planes(quantize_planes(planes)), scene.box, c2w, intr, size, size), ref)
    a, b = score(sec_torch), score(sec_ort)
    return {"secret_max_abs_diff": float(np.abs(sec_torch - sec_ort).max()), "restore_psnr_torch": a,
            "restore_psnr_onnx": b, "restore_psnr_diff_db": abs(a - b)}


def print_parity(graph_path, size: int = 96, severity: str = "moderate") -> dict:
    """The print medium's restore graph at `graph_path` (onnxruntime) against the numpy receiver it was written
    from (`print_read.despread` + `restore`): the shipped print scene hidden in a bundled host, read from the
    lossless snapshot and from the scan of a simulated `severity` photo of its sheet, both codecs' layouts;
    the planes' largest difference, the share of 8-bit codes that differ, and restore_psnr each way (rendered by the
    shipped graphs of the scene's decoder)."""
    from snapshot3d.cameras import orbit_cameras
    from snapshot3d.codecs import print_embed, print_feeds, print_read
    from snapshot3d.metrics import psnr
    from snapshot3d.paths import asset
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.qr import scene_meta
    from snapshot3d.scanner.roundtrip import capture
    from snapshot3d.scene import dequantize_planes, load_scene_file, quantize_planes
    from snapshot3d.viewer.render import render_views
    from snapshot3d.viewer.runtime import scene_models, session

    scene = load_scene_file(asset("spot-print.s3d"))
    r, c = scene.resolution, scene.channels
    c2w, intr = orbit_cameras(scene.orbit, formats.ORBIT_VIEWS, size)
    models = scene_models(scene)
    ref = render_views(models, scene.planes(), scene.box, c2w, intr, size, size)
    graph = session(str(graph_path))
    out = {}
    for codec in formats.PRINT_CODECS:
        snap = print_embed.embed(load_host("builtin:coffee"), scene.planes(), codec=codec)
        photo = capture(snap, scene_meta(scene, codec), severity, 0, sheet_dots=4)
        for name, img in (("lossless", snap), (severity, photo)):
            want, reading = print_read.restore(*print_read.despread(img, r, c, codec=codec), r, c, codec=codec)
            got, got_reading = graph.run(None, print_feeds.graph_feeds(img, r, c, codec))
            codes = [quantize_planes(x) for x in (want, got)]
            a, b = (psnr(render_views(models, dequantize_planes(q), scene.box, c2w, intr, size, size), ref) for q in codes)
            out[f"{codec} {name}"] = {
                "planes_max_abs_diff": float(np.abs(want - got).max()),
                "codes_differing": float(np.mean(codes[0] != codes[1])),
                "plane_rmse_expected_diff": abs(reading.plane_rmse - float(got_reading[2])),
                "restore_psnr_numpy": a, "restore_psnr_onnx": b, "restore_psnr_diff_db": abs(a - b)}
    return out


def print_graph_agrees(row: dict) -> bool:
    """One `print_parity` row passes: the same views to 0.05 dB, at most 1 in 1000 8-bit codes differing."""
    return row["restore_psnr_diff_db"] <= 0.05 and row["codes_differing"] <= 1e-3
