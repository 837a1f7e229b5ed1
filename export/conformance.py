"""Conformance vectors for third-party clients of the ONNX models (docs/onnx-contract.md): inputs and the
outputs the shipped graphs give for them, computed with onnxruntime (no torch), so that a port (onnxruntime
on a phone, onnxruntime-web) can check itself. `snapshot3d export ... --vectors FILE` writes them for the
models it just exported; `tests/test_onnx_contract.py` checks the shipped models against the committed ones.

FILE (.npz) holds, for the snapshot file `tests/data/spot-snapshot.png`:
- `restore_snapshot` uint8 (380, 380, 3) RGB: its pixels, the restore graph's input (as / 255, NCHW); they
  also carry the pixel metadata mark;
- `restore_secret` float16 (24, 95, 95): the restore graph's output without its batch axis (stored at half
  precision);
- `planes` float32 (3, C, R, R): the scene's planes after the documented unspread and 8-bit rounding;
- `project_interp` float32 (B, R), `project_tables` float32 (3, B*B, 32): the project graph's input
  (with `planes` zero-padded to 12 channels) and output, B = 16;
- `field_rows` int64 (M, 3), `field_density_logit` float32 (M,), `field_rgb` float32 (M, 3), `field_hidden`
  float32 (M, 32): the field graph's input (with `project_tables`) and outputs for M = 64 grid cells;
- `meta` (text): the snapshot's metadata payload (the QR text);
- `mark_slots` int32 (6200,) and `mark_dither` float64 (6627,): the pixel mark's slot permutation (the first
  6200 entries, all any frame uses) and its dithers per slot in units of the frame's step;
- the print medium's restore graph, for the scan of the demo's example photo (`snapshot3d/assets/
  example-photo.jpg`, a `moderate` photo of a `print-2` sheet): `print_capture` uint8 (380, 380, 3) RGB (the
  rectified, colour-corrected capture; the graph's `snapshot` is it / 255, NCHW), `print_meta` (its QR text),
  `print_<name>` for each layout input of `snapshot3d.codecs.print_feeds.LAYOUT_INPUTS` (index arrays stored as
  int32: feed them as int64), and the outputs `print_planes` float32 (3, C, R, R) (the raw graph output, not
  clipped) and `print_reading` float32 (3,).
Tolerances: docs/onnx-contract.md, "Conformance vectors" (the same as tests/test_onnx_contract.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["VECTORS_INPUT", "GRID", "POINTS", "make_vectors", "mark_vectors", "render_vectors", "print_vectors",
           "write_vectors"]

VECTORS_INPUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "spot-snapshot.png"
GRID = 16
POINTS = 64


def make_vectors(models: dict, snapshot_png: Path = VECTORS_INPUT) -> dict:
    """models: kind -> .onnx path ('restore', 'project', 'field') -> the arrays above."""
    from snapshot3d.codecs import file_layout
    from snapshot3d.images import snapshot_nchw
    from snapshot3d.scanner.qr import encode_payload
    from snapshot3d.scanner.snapfile import read_snapshot
    from snapshot3d.scene import dequantize_planes, quantize_planes
    from snapshot3d.viewer.runtime import session

    rgb, meta = read_snapshot(snapshot_png, None)
    res, channels = meta.planes
    secret = session(str(models["restore"])).run(None, {"snapshot": snapshot_nchw(rgb)})[0][0]
    planes = dequantize_planes(quantize_planes(file_layout.secret_to_planes(secret / (meta.strength or 1.0), res,
                                                                             channels)))
    return {"restore_snapshot": rgb, "restore_secret": secret.astype(np.float16), "planes": planes,
            "meta": np.array(encode_payload(meta)), **mark_vectors(), **render_vectors(models, planes),
            **print_vectors(models["restore-print"])}


def mark_vectors() -> dict:
    """`mark_slots` and `mark_dither` above (the frame `pixelmeta.FRAME` uses the most slots; its step is a
    power of two, so the dithers divide by it exactly)."""
    from snapshot3d.scanner import pixelmeta

    _, slots, dither = pixelmeta._code(pixelmeta.FRAME)
    return {"mark_slots": slots.reshape(-1).astype(np.int32), "mark_dither": dither / pixelmeta.FRAME.step}


def render_vectors(models: dict, planes: np.ndarray) -> dict:
    """The `project_*` and `field_*` arrays above for `planes` (3, C, R, R) float32: the renderer's graphs on
    given planes, so that a check of these graphs does not inherit a plane code that rounded the other way
    upstream (one 8-bit step in one plane value moves a logit by up to 3e-2)."""
    from snapshot3d.viewer.bake import cell_coords, interp_matrix
    from snapshot3d.viewer.render import pad_planes
    from snapshot3d.viewer.runtime import session

    interp = interp_matrix(cell_coords(GRID), planes.shape[-1])
    tables = session(str(models["project"])).run(None, {"planes": pad_planes(planes), "interp": interp})[0]
    cells = np.random.default_rng(0).integers(0, GRID, (POINTS, 3))
    rows = np.stack([cells[:, 1] * GRID + cells[:, 0], cells[:, 2] * GRID + cells[:, 0],
                     cells[:, 2] * GRID + cells[:, 1]], 1).astype(np.int64)
    logit, colour, hidden = session(str(models["field"])).run(["density_logit", "rgb", "hidden"],
                                                              {"tables": tables, "rows": rows})
    return {"project_interp": interp, "project_tables": tables, "field_cells": cells.astype(np.int64),
            "field_rows": rows, "field_density_logit": logit, "field_rgb": colour, "field_hidden": hidden}


def print_vectors(graph_path, photo: Path | None = None) -> dict:
    """The `print_*` arrays above, for the scan of `photo` (default the demo's example photo)."""
    from snapshot3d.codecs import print_feeds
    from snapshot3d.paths import asset
    from snapshot3d.scanner.qr import encode_payload
    from snapshot3d.viewer.decode import read_input
    from snapshot3d.viewer.runtime import session

    _, capture, meta, _ = read_input(photo or asset("example-photo.jpg"))
    feeds = print_feeds.graph_feeds(capture, *meta.planes, meta.codec)
    planes, reading = session(str(graph_path)).run(None, feeds)
    layout = {f"print_{k}": (v.astype(np.int32) if v.dtype == np.int64 else v) for k, v in feeds.items()
              if k != "snapshot"}
    return {"print_capture": capture, "print_meta": np.array(encode_payload(meta)), **layout,
            "print_planes": planes, "print_reading": reading}


def write_vectors(path, models: dict) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "wb") as f:
        np.savez_compressed(f, **make_vectors(models))
    tmp.replace(path)
