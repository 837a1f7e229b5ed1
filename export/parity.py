"""torch against onnxruntime on real inputs (the shipped spot scene, a real host): the checks the
export command reports and the tests assert."""
from __future__ import annotations

import numpy as np
import torch

from snapshot3d import formats

__all__ = ["shade_parity", "restore_parity"]


def _spot():
    from snapshot3d.paths import asset
    from snapshot3d.scene import load_scene_file
    return load_scene_file(asset("spot.s3d"))


def shade_parity(shade_path, size: int = 96) -> dict:
    """Max abs difference of the views of spot's planes: the same samples shaded by torch and ORT."""
    from snapshot3d.train.decoder import load_decoder
    from snapshot3d.cameras import orbit_cameras
    from snapshot3d.viewer.render import render_views
    from snapshot3d.viewer.runtime import session

    from .models import ShadeGraph

    scene = _spot()
    graph = ShadeGraph(load_decoder()).eval()

    class _TorchSess:  # the ORT session's `run`, computed by torch
        def run(self, _, feeds):
            with torch.no_grad():
                return [t.numpy() for t in graph(*(torch.from_numpy(feeds[k]) for k in ("planes", "points", "delta")))]

    c2w, intr = orbit_cameras(scene.orbit, 3, size)
    ort_views = render_views(session(str(shade_path)), scene.planes(), scene.box, c2w, intr, size, size)
    torch_views = render_views(_TorchSess(), scene.planes(), scene.box, c2w, intr, size, size)
    return {"views_max_abs_diff": float(np.abs(ort_views - torch_views).max())}


def restore_parity(restore_path, shade_path, size: int = 96) -> dict:
    """restore_psnr of spot hidden in a bundled host, restored by torch and by ORT (same renderer)."""
    from snapshot3d import codec_layout
    from snapshot3d.metrics import psnr
    from snapshot3d.scene import dequantize_planes, quantize_planes
    from snapshot3d.train.codec import embed_planes, load_codec, restore_secret
    from snapshot3d.train.codec_commands import load_host
    from snapshot3d.cameras import orbit_cameras
    from snapshot3d.viewer.render import render_views
    from snapshot3d.viewer.runtime import session

    scene = _spot()
    net, _ = load_codec()
    snap = embed_planes(net, load_host("builtin:coffee"), scene.planes())
    sec_torch = restore_secret(net, snap)
    x = (snap.astype(np.float32) / 255.0).transpose(2, 0, 1)[None]
    sec_ort = session(str(restore_path)).run(None, {"snapshot": np.ascontiguousarray(x)})[0][0]
    c2w, intr = orbit_cameras(scene.orbit, formats.ORBIT_VIEWS, size)
    shade = session(str(shade_path))
    ref = render_views(shade, scene.planes(), scene.box, c2w, intr, size, size)

    def score(secret):
        planes = codec_layout.secret_to_planes(secret, scene.resolution, scene.channels)
        return psnr(render_views(shade, dequantize_planes(quantize_planes(planes)), scene.box, c2w, intr, size, size), ref)
    a, b = score(sec_torch), score(sec_ort)
    return {"secret_max_abs_diff": float(np.abs(sec_torch - sec_ort).max()), "restore_psnr_torch": a,
            "restore_psnr_onnx": b, "restore_psnr_diff_db": abs(a - b)}
