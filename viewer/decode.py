"""Photo -> turnable scene, without torch: scan (OpenCV) -> restore (ONNX) -> render (numpy + ONNX).

`decode_photo` returns the views (N, size, size, 3) float32 RGB in [0, 1], the restored scene and a
report with `detected`, `confidence`, `timings_ms` per stage, `decode_ms` (photo file to all views in
memory) and a quality estimate that needs no ground truth (`viewer.quality`: the sheet's markers as a
pilot signal, and the `restore_psnr` they predict)."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from snapshot3d import formats
from snapshot3d.cameras import orbit_cameras
from snapshot3d.errors import UserError
from snapshot3d.scene import Orbit, Scene, quantize_planes

from .bake import Baked, bake_field
from .march import Frame
from .media import restore_planes
from .quality import quality_estimate
from .render import RenderConfig, pad_planes, render_views
from .runtime import field_models

__all__ = ["Decoded", "decode_photo", "scene_from_meta"]


@dataclass
class Decoded:
    views: np.ndarray
    scene: Scene
    report: dict
    baked: Baked


def scene_from_meta(codes: np.ndarray, meta) -> Scene:
    box = np.asarray(meta.box, np.float32).reshape(2, 3)
    target = tuple(meta.target) if meta.target else tuple(float(v) for v in box.mean(0))
    if meta.orbit:
        r, el, fov = meta.orbit
    else:
        r, el, fov = float(np.linalg.norm(box[1] - box[0])), formats.ORBIT_ELEVATION_DEG, formats.ORBIT_FOV_DEG
    return Scene(codes=codes, box=box, orbit=Orbit(r, el, fov, target), name="decoded")


def _meta(qr: dict | None):
    from snapshot3d.scanner.qr import SheetMeta, check_codec

    if qr is None:
        raise UserError("found the sheet but could not read its QR code (it holds the scene box and plane size); "
                        "retake the photo closer and sharper")
    meta = SheetMeta(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in qr.items()})
    check_codec(meta)
    if meta.planes is None or meta.box is None:
        raise UserError("the sheet's QR code lacks the plane size or the scene box (a sheet made without a scene)")
    return meta


def decode_photo(path, views: int = formats.ORBIT_VIEWS, size: int = formats.ORBIT_SIZE,
                 cfg: RenderConfig = RenderConfig(), on_view=None) -> Decoded:
    from snapshot3d.scanner.scan import scan_file

    t0 = time.perf_counter()
    res = scan_file(path)
    meta = _meta(res.qr)
    t1 = time.perf_counter()
    planes, codec_info = restore_planes(res.snapshot, meta)
    t2 = time.perf_counter()
    scene = scene_from_meta(quantize_planes(planes), meta)
    models = field_models()
    baked = bake_field(models, pad_planes(planes), Frame.from_box(scene.box), cfg.bake)
    t3 = time.perf_counter()
    c2w, intr = orbit_cameras(scene.orbit, views, size)
    first = []

    def _tick(i):  # may run on worker threads: list.append is atomic
        if not first:
            first.append(time.perf_counter())
        if on_view is not None:
            on_view(i)
    out = render_views(models, planes, scene.box, c2w, intr, size, size, cfg, baked=baked, on_view=_tick)
    t4 = time.perf_counter()
    ms = lambda a, b: round((b - a) * 1e3, 1)  # noqa: E731
    report = {
        "detected": True, "confidence": round(float(res.confidence), 3),
        "timings_ms": {"scan": ms(t0, t1), "restore": ms(t1, t2), "bake": ms(t2, t3), "render": ms(t3, t4),
                       "first_view": ms(t0, first[0]) if first else None},
        "decode_ms": ms(t0, t4),
        "codec": meta.codec, "medium": formats.CODEC_MEDIUM[meta.codec],
        "quality_estimate": quality_estimate(meta.codec, res.pilot_psnr, codec_info.get("plane_rmse_expected")),
        "planes": list(meta.planes), "views": views, "size": size, "render": cfg.__dict__,
        "field_evaluations": baked.evaluated,
        "scan": {k: v for k, v in res.report().items() if k in ("corners", "reprojection_px", "qr")},
    }
    return Decoded(out, scene, report, baked)
