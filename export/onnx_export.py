"""torch -> ONNX for the restore network and the renderer's shading graph: pinned opset, fixed input
and output names, metadata (codec id, decoder version, orbit), `onnx.checker`, and a parity check
against torch on the same inputs (an export that drifts fails; it is never skipped)."""
from __future__ import annotations

import io
import time
from pathlib import Path

import torch

from snapshot3d import formats
from snapshot3d.paths import model_file

from .models import RESTORE_INPUTS, RESTORE_OUTPUTS, SHADE_INPUTS, SHADE_OUTPUTS, RestoreGraph, ShadeGraph

__all__ = ["OPSET", "export_restore", "export_shade", "export_all", "model_names"]

OPSET = 17


def model_names() -> dict:
    """File names of the two models (they carry the versions they were made from)."""
    return {k: model_file(k) for k in ("restore", "shade")}


def _metadata() -> dict:
    return {"codec_id": formats.CODEC_VERSION, "decoder_version": formats.DECODER_VERSION,
            "snapshot_size": str(formats.SNAPSHOT_SIZE), "orbit_views": str(formats.ORBIT_VIEWS),
            "orbit_size": str(formats.ORBIT_SIZE), "orbit_elevation_deg": str(formats.ORBIT_ELEVATION_DEG),
            "orbit_fov_deg": str(formats.ORBIT_FOV_DEG), "c_max": str(formats.C_MAX), "opset": str(OPSET)}


def _finish(buf: bytes, path: Path, producer: str) -> int:
    import onnx

    model = onnx.load_from_string(buf)
    for k, v in _metadata().items():
        model.metadata_props.append(onnx.StringStringEntryProto(key=k, value=v))
    model.producer_name = producer
    onnx.checker.check_model(model, full_check=True)
    data = model.SerializeToString()
    tmp = path.with_name(path.name + ".partial")
    tmp.write_bytes(data)
    tmp.replace(path)
    return len(data)


def _export(module, args, names_in, names_out, dynamic, path: Path, producer: str) -> int:
    buf = io.BytesIO()
    with torch.no_grad():
        torch.onnx.export(module, args, buf, input_names=names_in, output_names=names_out, opset_version=OPSET,
                          dynamic_axes=dynamic, do_constant_folding=True, dynamo=False)
    return _finish(buf.getvalue(), path, producer)


def export_restore(codec, path: Path) -> int:
    s = formats.SNAPSHOT_SIZE
    x = torch.rand(1, 3, s, s)
    return _export(RestoreGraph(codec).eval(), (x,), RESTORE_INPUTS, RESTORE_OUTPUTS, None, path,
                   "snapshot3d restore")


def export_shade(decoder, path: Path) -> int:
    planes = torch.rand(3, formats.C_MAX, 64, 64) * 2 - 1
    pts = torch.rand(128, 16, 3) * 2 - 1
    dynamic = {"planes": {2: "R", 3: "R"}, "points": {0: "N", 1: "S"}, "delta": {0: "N", 1: "S"},
               "rgb": {0: "N"}, "acc": {0: "N"}}
    return _export(ShadeGraph(decoder).eval(), (planes, pts, torch.full((128, 16), 0.02)), SHADE_INPUTS, SHADE_OUTPUTS,
                   dynamic, path, "snapshot3d shade")


def export_all(out: Path, log=print) -> dict:
    """Write both models into `out`; returns their paths and sizes."""
    from snapshot3d.train.codec import load_codec
    from snapshot3d.train.decoder import load_decoder

    out.mkdir(parents=True, exist_ok=True)
    names = model_names()
    t0 = time.time()
    sizes = {"restore": export_restore(load_codec()[0], out / names["restore"]),
             "shade": export_shade(load_decoder(), out / names["shade"])}
    log(f"exported {', '.join(f'{names[k]} ({v / 1e6:.2f} MB)' for k, v in sizes.items())} in {time.time() - t0:.1f} s")
    return {k: {"path": str(out / names[k]), "bytes": v} for k, v in sizes.items()}
