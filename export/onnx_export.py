"""torch -> ONNX for the restore network and the renderer's two field graphs: pinned opset, fixed input
and output names, metadata (codec id, decoder version, orbit), `onnx.checker`, and a parity check
against torch on the same inputs (an export that drifts fails; it is never skipped)."""
from __future__ import annotations

import io
import time
from pathlib import Path

import torch

from snapshot3d import formats
from snapshot3d.paths import model_file

from .models import (
    FIELD_INPUTS,
    FIELD_OUTPUTS,
    PROJECT_INPUTS,
    PROJECT_OUTPUTS,
    RESTORE_INPUTS,
    RESTORE_OUTPUTS,
    FieldGraph,
    ProjectGraph,
    RestoreGraph,
)

__all__ = ["OPSET", "MODEL_KINDS", "export_restore", "export_project", "export_field", "export_all", "model_names"]

OPSET = 17
MODEL_KINDS = ("restore", "project", "field")


def model_names() -> dict:
    """File names of the models (they carry the versions they were made from)."""
    return {k: model_file(k) for k in MODEL_KINDS}


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


def export_project(decoder, path: Path) -> int:
    planes = torch.rand(3, formats.C_MAX, 64, 64) * 2 - 1
    dynamic = {"planes": {2: "R", 3: "R"}, "interp": {0: "B", 1: "R"}, "tables": {1: "T"}}
    return _export(ProjectGraph(decoder).eval(), (planes, torch.rand(96, 64)), PROJECT_INPUTS, PROJECT_OUTPUTS,
                   dynamic, path, "snapshot3d project")


def export_field(decoder, path: Path) -> int:
    tables = torch.rand(3, 96 * 96, decoder.hidden)
    dynamic = {"tables": {1: "T"}, "rows": {0: "M"}, "density_logit": {0: "M"}, "rgb": {0: "M"}}
    return _export(FieldGraph(decoder).eval(), (tables, torch.randint(0, 96 * 96, (2048, 3))), FIELD_INPUTS,
                   FIELD_OUTPUTS, dynamic, path, "snapshot3d field")


def export_all(out: Path, log=print) -> dict:
    """Write the models into `out`; returns their paths and sizes."""
    from snapshot3d.train.codec.hinet import load_codec
    from snapshot3d.train.field.decoder import load_decoder

    out.mkdir(parents=True, exist_ok=True)
    names = model_names()
    t0 = time.time()
    decoder = load_decoder()
    sizes = {"restore": export_restore(load_codec()[0], out / names["restore"]),
             "project": export_project(decoder, out / names["project"]),
             "field": export_field(decoder, out / names["field"])}
    log(f"exported {', '.join(f'{names[k]} ({v / 1e6:.2f} MB)' for k, v in sizes.items())} in {time.time() - t0:.1f} s")
    return {k: {"path": str(out / names[k]), "bytes": v} for k, v in sizes.items()}
