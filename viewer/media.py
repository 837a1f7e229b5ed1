"""Restoring planes from a (rectified) snapshot with the codec its metadata names, torch-free: the `file`
medium's invertible network (one ONNX graph, then the least-squares unspread) or the `print` medium's
designed carrier receiver (one ONNX graph, `restore-print.onnx`, fed the layout of the snapshot's plane size
and codec: a linear receiver, and for `print-2` the posterior of its folded carriers; the numpy code of
`snapshot3d.codecs.print_read` is its reference). The medium is the one `codecs.media.medium_of` gives the
codec (an unknown codec id is refused in one line); `RESTORERS` holds each medium's restorer.

Layouts: snapshot (380, 380, 3) uint8 RGB; planes (3, C, R, R) float32 in [-1, 1], rounded to the 8-bit
values a scene carries."""
from __future__ import annotations

import numpy as np

from snapshot3d import formats
from snapshot3d.codecs import file_layout, print_feeds, print_read
from snapshot3d.codecs.media import medium_of
from snapshot3d.images import snapshot_nchw
from snapshot3d.scene import dequantize_planes, quantize_planes

from .runtime import model_path, session

__all__ = ["restore_planes", "restore_file", "restore_print", "onnx_runner", "RESTORERS"]


def onnx_runner(kind: str, codec: str | None = None):
    """x (1, 3, 380, 380) float32 -> the model's only output, through onnxruntime (kind, codec as `model_path`)."""
    sess = session(str(model_path(kind, codec)))
    return lambda x: sess.run(None, {"snapshot": np.ascontiguousarray(x, np.float32)})[0]


def restore_file(snapshot: np.ndarray, res: int, channels: int, strength: float = 1.0, run=None,
                 codec: str = formats.FILE_CODEC) -> np.ndarray:
    """The file medium: planes from the secret of `codec`'s invertible network (`run` replaces its ONNX graph)."""
    secret = (run or onnx_runner("restore", codec))(snapshot_nchw(snapshot))[0] / strength
    return file_layout.secret_to_planes(secret, res, channels)


def restore_print(snapshot: np.ndarray, res: int, channels: int, graph=None,
                  codec: str = formats.PRINT_CODEC, front=None) -> tuple[np.ndarray, print_read.Reading]:
    """The print medium: the capture read carrier by carrier (matched filters shaped and weighted by the
    capture's brightness, the bands combined as the pilots measure them), MMSE with the gain and noise the
    pilots measure, by the restore graph (`graph`: anything with an onnxruntime session's `run` in its place;
    default the shipped `restore-print.onnx`). Returns planes and the pilots' `Reading` (an estimate of the
    planes' error, no ground truth needed). `codec`: the print codec id the snapshot names (its carriers).
    `front` (x (1, 3, 380, 380) -> payload estimate, same layout) puts a learned front-end before the numpy
    receiver: the bench's `print-front` row; the product reads the capture itself, which measured better
    (docs/print-codec.md, "Dropped designs")."""
    if front is not None:
        restored = front(snapshot_nchw(snapshot))[0].transpose(1, 2, 0)
        read, factor = print_read.despread(restored, res, channels, capture=snapshot, codec=codec)
        return print_read.restore(read, factor, res, channels, codec=codec)
    sess = graph or session(str(model_path("restore-print")))
    planes, reading = sess.run(None, print_feeds.graph_feeds(snapshot, res, channels, codec))
    return planes, print_feeds.reading_of(reading)


def _file_planes(snapshot: np.ndarray, meta, runners: dict) -> tuple[np.ndarray, dict]:
    res, channels = meta.planes
    return restore_file(snapshot, res, channels, meta.strength or 1.0, runners.get("restore"), meta.codec), {}


def _print_planes(snapshot: np.ndarray, meta, runners: dict) -> tuple[np.ndarray, dict]:
    res, channels = meta.planes
    planes, reading = restore_print(snapshot, res, channels, runners.get("restore-print"), meta.codec,
                                    runners.get("print-front"))
    return planes, {"plane_rmse_expected": round(reading.plane_rmse, 4), "pilot_gain": round(reading.gain, 4),
                    "pilot_noise": float(f"{reading.noise:.4g}")}


RESTORERS = {"file": _file_planes, "print": _print_planes}
"""medium name -> (snapshot, meta, runners) -> (planes (3, C, R, R) float32 as restored, what the codec says of
its own reading)"""


def restore_planes(snapshot: np.ndarray, meta, runners: dict | None = None) -> tuple[np.ndarray, dict]:
    """Planes (3, C, R, R) as carried (8-bit values) from a rectified snapshot and its metadata
    (`scanner.qr.SheetMeta`), with the codec the metadata names; and what the codec says of its own
    reading ({"plane_rmse_expected": ...} for the print codec, {} for the file codec). `runners` may
    replace the ONNX graphs by kind ('restore', 'restore-print': tests compare them with torch and numpy)
    or put a learned front-end before the print receiver ('print-front', the bench's)."""
    planes, info = RESTORERS[medium_of(meta.codec).name](snapshot, meta, runners or {})
    return dequantize_planes(quantize_planes(planes)), info
