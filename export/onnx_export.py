"""torch -> ONNX for the restore graphs (each file codec's network, and the print medium's designed receiver)
and the renderer's two field graphs: pinned opset, fixed input and output names, metadata (codec id, decoder
version, orbit), `onnx.checker`, and a parity check against torch (the file codecs, the renderer) or the
numpy reference (the print receiver) on the same inputs (an export that drifts fails; it is never skipped)."""
from __future__ import annotations

import io
import time
from pathlib import Path

import numpy as np
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

__all__ = ["OPSET", "MODEL_KINDS", "DOCS", "export_restore", "export_restore_print", "export_project", "export_field",
           "export_all", "restore_keys"]

OPSET = 17
MODEL_KINDS = ("restore", "restore-print", "project", "field")
# Each graph's contract, written into the model as its doc string (docs/onnx-contract.md says it in full).
DOCS = {
    "restore": "file medium (the codec named by the metadata's codec_id and the file name). Input snapshot: float32 (1, 3, 380, 380), RGB, NCHW, values in [0, 1] "
               "(uint8 / 255). Output secret: float32 (1, 24, 95, 95): plane k's channel c at index 8k + c (planes xy, "
               "xz, yz); divide by the strength in the metadata, then planes = P S P^T per channel with P = pinv(U), U "
               "(95, R) the linear interpolation of R texel centres onto 95 cell centres (snapshot3d/codecs/file_layout.py).",
    "restore-print": "print medium (every print codec, every plane size: the layout of the metadata's codec_id and "
                     "plane size comes in as inputs, snapshot3d/codecs/print_feeds.py). Input snapshot: float32 (1, 3, 380, "
                     "380), RGB, NCHW, in [0, 1] (the scanner's rectified capture, uint8 / 255); chips int64 (N, K), base "
                     "float32 (N, K), place int64 (3*C*R*R,), scale and prior float32 (M,), pilots float32 (256,), folded "
                     "int64 (F,), fold_amp float32 (F,), dct float32 (R, R), prior_rest float32 () (rank 0). Outputs planes: "
                     "float32 (3, C, R, R), not clipped (clip to [-1, 1], round to 8 bits to store them); reading: "
                     "float32 (3,): the pilots' gain, noise per carrier and the planes' expected RMS error.",
    "project": "renderer, part 1. Inputs planes: float32 (3, 12, R, R) in [-1, 1] (planes xy, xz, yz; channels beyond "
               "the scene's zero); interp: float32 (B, R), the bilinear weights of B grid coordinates over R texels. "
               "Output tables: float32 (3, B*B, H), the decoder's first layer (without bias) at every grid node; H is "
               "the decoder's width (tri-dec-1: 32, tri-dec-2: 64; decoder_version in this graph's metadata).",
    "field": "renderer, part 2. Inputs tables: float32 (3, T, H) from project (H the decoder's width); rows: int64 (M, 3), the table row of each "
             "point in each plane. Outputs density_logit: float32 (M,) (density = exp, clamped at 15); rgb: float32 "
             "(M, 3) in [0, 1]; hidden: float32 (M, H), the last hidden layer, for a scene with its own head "
             "(metadata h=): out = hidden W^T + b, density_logit = min(out0, 15), rgb = sigmoid(out1..3).",
}


def _metadata(codec: str | None, decoder: str | None = None) -> dict:
    """The metadata of every graph; `codec`: the codec ids a restore graph reads (comma-separated, e.g.
    'print-2,print-1'), None for the renderer's graphs, which every codec shares (they name no codec);
    `decoder`: the renderer graphs' decoder version (default, and for restore graphs, the current one)."""
    return {**({"codec_id": codec} if codec else {}), "decoder_version": decoder or formats.DECODER_VERSION,
            "snapshot_size": str(formats.SNAPSHOT_SIZE), "orbit_views": str(formats.ORBIT_VIEWS),
            "orbit_size": str(formats.ORBIT_SIZE), "orbit_elevation_deg": str(formats.ORBIT_ELEVATION_DEG),
            "orbit_fov_deg": str(formats.ORBIT_FOV_DEG), "c_max": str(formats.C_MAX), "opset": str(OPSET)}


def _finish(buf: bytes, path: Path, producer: str, kind: str, codec: str | None, out_shapes: dict | None = None,
            decoder: str | None = None) -> int:
    """Metadata, doc string and declared output shapes (`out_shapes`: name -> dims, int or symbolic name,
    where the exporter left a dimension it could not name), checked, written atomically."""
    import onnx

    model = onnx.load_from_string(buf)
    for out in model.graph.output:
        for dim, want in zip(out.type.tensor_type.shape.dim, (out_shapes or {}).get(out.name, ())):
            if isinstance(want, int):
                dim.dim_value = want
            else:
                dim.dim_param = want
    for k, v in _metadata(codec, decoder).items():
        model.metadata_props.append(onnx.StringStringEntryProto(key=k, value=v))
    model.producer_name = producer
    model.doc_string = DOCS[kind]
    onnx.checker.check_model(model, full_check=True)
    data = model.SerializeToString()
    tmp = path.with_name(path.name + ".partial")
    tmp.write_bytes(data)
    tmp.replace(path)
    return len(data)


def _export(module, args, names_in, names_out, dynamic, path: Path, kind: str, codec: str | None = None,
            out_shapes: dict | None = None, decoder: str | None = None) -> int:
    buf = io.BytesIO()
    with torch.no_grad():
        torch.onnx.export(module, args, buf, input_names=names_in, output_names=names_out, opset_version=OPSET,
                          dynamic_axes=dynamic, do_constant_folding=True, dynamo=False)
    return _finish(buf.getvalue(), path, f"snapshot3d {kind}", kind, codec, out_shapes, decoder)


def export_restore(codec, path: Path, codec_id: str = formats.FILE_CODEC) -> int:
    """The restore graph of `codec` (a loaded file codec network), its metadata naming `codec_id`."""
    s = formats.SNAPSHOT_SIZE
    x = torch.rand(1, 3, s, s)
    return _export(RestoreGraph(codec).eval(), (x,), RESTORE_INPUTS, RESTORE_OUTPUTS, None, path, "restore",
                   codec=codec_id)


def export_restore_print(path: Path) -> int:
    """The print medium's restore graph (`export.print_graph`), traced on the current codec's 16x4 layout; every
    layout dimension is dynamic, so it reads any plane size and both print codecs."""
    from snapshot3d.codecs import print_feeds

    from .print_graph import PrintRestoreGraph

    s = formats.SNAPSHOT_SIZE
    feeds = print_feeds.graph_feeds((torch.rand(s, s, 3) * 255).to(torch.uint8).numpy(), 16, 4)
    args = tuple(torch.from_numpy(np.asarray(feeds[k])) for k in print_feeds.PRINT_GRAPH_INPUTS)
    dynamic = {"chips": {0: "N", 1: "K"}, "base": {0: "N", 1: "K"}, "place": {0: "S"}, "scale": {0: "M"},
               "prior": {0: "M"}, "folded": {0: "F"}, "fold_amp": {0: "F"}, "dct": {0: "R", 1: "R"},
               "planes": {1: "C", 2: "R", 3: "R"}}
    return _export(PrintRestoreGraph().eval(), args, print_feeds.PRINT_GRAPH_INPUTS, print_feeds.PRINT_GRAPH_OUTPUTS,
                   dynamic, path, "restore-print", codec=",".join(formats.PRINT_CODECS),
                   out_shapes={"planes": [3, "C", "R", "R"], "reading": [3]})


def export_project(decoder, path: Path, version: str = formats.DECODER_VERSION) -> int:
    """The renderer's project graph of `decoder` (a loaded shared decoder of version `version`)."""
    planes = torch.rand(3, formats.C_MAX, 64, 64) * 2 - 1
    dynamic = {"planes": {2: "R", 3: "R"}, "interp": {0: "B", 1: "R"}, "tables": {1: "T"}}
    return _export(ProjectGraph(decoder).eval(), (planes, torch.rand(96, 64)), PROJECT_INPUTS, PROJECT_OUTPUTS,
                   dynamic, path, "project", out_shapes={"tables": [3, "T", decoder.hidden]}, decoder=version)


def export_field(decoder, path: Path, version: str = formats.DECODER_VERSION) -> int:
    """The renderer's field graph of `decoder` (version `version`)."""
    tables = torch.rand(3, 96 * 96, decoder.hidden)
    dynamic = {"tables": {1: "T"}, "rows": {0: "M"}, "density_logit": {0: "M"}, "rgb": {0: "M"}, "hidden": {0: "M"}}
    return _export(FieldGraph(decoder).eval(), (tables, torch.randint(0, 96 * 96, (2048, 3))), FIELD_INPUTS,
                   FIELD_OUTPUTS, dynamic, path, "field", decoder=version)


def decoder_keys() -> dict:
    """export.json's key of each renderer graph -> (graph, decoder version): 'project' and 'field' are the current
    decoder's, those of the versions older scenes name (`formats.DECODERS`) are 'project-<version>', 'field-<version>'."""
    return {(g if d == formats.DECODER_VERSION else f"{g}-{d}"): (g, d) for d in formats.DECODERS
            for g in ("project", "field")}


def restore_keys() -> dict:
    """export.json's key of each file codec's restore graph -> codec: 'restore' is the current codec's, the
    codecs older snapshots name (`formats.FILE_CODECS`) are 'restore-<codec>'."""
    return {("restore" if c == formats.FILE_CODEC else f"restore-{c}"): c for c in formats.FILE_CODECS}


def export_all(out: Path, log=print) -> dict:
    """Write the models into `out` (the restore graph of every file codec this build reads, the print medium's
    restore graph, and the renderer's two graphs of every decoder version this build reads); returns their paths
    and sizes, keyed as in `restore_keys`, 'restore-print' and `decoder_keys`."""
    from snapshot3d.train.codec.hinet import codec_path, load_codec
    from snapshot3d.train.field.decoder import load_decoder

    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    names = {k: model_file("restore", c) for k, c in restore_keys().items()}
    names["restore-print"] = model_file("restore-print")
    names.update({k: model_file(g, decoder=d) for k, (g, d) in decoder_keys().items()})
    sizes = {k: export_restore(load_codec(codec_path(c))[0], out / names[k], c) for k, c in restore_keys().items()}
    sizes["restore-print"] = export_restore_print(out / names["restore-print"])
    for k, (g, d) in decoder_keys().items():
        sizes[k] = (export_project if g == "project" else export_field)(load_decoder(d), out / names[k], d)
    log(f"exported {', '.join(f'{names[k]} ({v / 1e6:.2f} MB)' for k, v in sizes.items())} in {time.time() - t0:.1f} s")
    return {k: {"path": str(out / names[k]), "bytes": v} for k, v in sizes.items()}
