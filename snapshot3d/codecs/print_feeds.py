"""The print codec's layout as the inputs of its ONNX restore graph (`restore-print.onnx`; numpy, torch-free).

The graph (`export.print_graph`) is the designed receiver of `codecs.print_read` (matched filters
shaped by the capture's brightness, the bands combined as the pilots measure them, linear MMSE, and the
folded coefficients' posterior of `codecs.print_fold`) with nothing of a plane size in it: one graph
reads every plane size and both print codecs, and the layout of the snapshot's plane size and codec comes in
as data. `docs/onnx-contract.md` section 4 states each array.

Feeds (`LAYOUT_INPUTS` order; N carriers of K chips, M linear coefficients, F folded ones, P = `PILOTS`):
- chips int64 (N, K): each carrier's chips, indices into the flat pool of the `PRINT_BANDS` coefficients;
- base float32 (N, K): the carrier's entries before the capture's brightness shapes them;
- place int64 (3*C*R*R,): for every DCT coefficient of the planes (plane-major, channel, row v, column u),
  its index among the M linear coefficients, or M when no carrier holds it (it restores as 0);
- scale, prior float32 (M,): each coefficient's amplitude per unit at strength 1, and its expected square;
- pilots float32 (P,): the pilots' values (amplitude times sign);
- folded int64 (F,): indices among the M coefficients of those also carried on a helix (none in `print-1`);
- fold_amp float32 (F,): their helix carriers' amplitude;
- dct float32 (R, R): the orthonormal DCT-II matrix, D[k, n] = sqrt((1 if k == 0 else 2) / R) cos(pi (2n + 1) k / 2R);
- prior_rest float32 (): the prior power of the coefficients no carrier holds (for the expected error).
"""
from __future__ import annotations

import io
from functools import lru_cache

import numpy as np

from snapshot3d import formats
from snapshot3d.images import snapshot_nchw

from .print_carriers import PRINT_BANDS, PrintLayout, print_layout
from .print_read import Reading
from .print_source import prior_spectrum

__all__ = ["LAYOUT_INPUTS", "PRINT_GRAPH_INPUTS", "PRINT_GRAPH_OUTPUTS", "dct_matrix", "layout_feeds",
           "graph_feeds", "reading_of", "layout_npz"]

LAYOUT_INPUTS = ["chips", "base", "place", "scale", "prior", "pilots", "folded", "fold_amp", "dct", "prior_rest"]
PRINT_GRAPH_INPUTS = ["snapshot"] + LAYOUT_INPUTS
PRINT_GRAPH_OUTPUTS = ["planes", "reading"]
"""planes float32 (3, C, R, R): the MMSE estimate, not clipped or rounded; reading float32 (3,): the pilots'
gain, the noise power per carrier of average noise factor, and the planes' expected RMS error"""


def dct_matrix(res: int) -> np.ndarray:
    """(res, res) float64 orthonormal DCT-II: cv2.dct(x) == D @ x @ D.T, cv2.idct(c) == D.T @ c @ D."""
    k, n = np.meshgrid(np.arange(res), np.arange(res), indexing="ij")
    d = np.cos(np.pi * (2 * n + 1) * k / (2 * res)) * np.sqrt(2.0 / res)
    d[0] /= np.sqrt(2.0)
    return d


def layout_feeds(lay: PrintLayout) -> dict[str, np.ndarray]:
    """A layout (`print_carriers.print_layout`) as the graph's layout inputs (see the module doc)."""
    if lay.bands != PRINT_BANDS:
        raise ValueError("the restore graph reads the codec's own bands (print_carriers.PRINT_BANDS) only")
    res, m = lay.res, len(lay.coef)
    size = 3 * lay.channels * res * res
    place = np.full(size, m, np.int64)
    place[lay.coef] = np.arange(m)
    rest = np.tile(prior_spectrum(res).ravel(), 3 * lay.channels)[place == m].sum()
    f32 = (lambda x: np.ascontiguousarray(x, np.float32))
    return {"chips": lay.chips.astype(np.int64), "base": f32(lay.base), "place": place, "scale": f32(lay.scale),
            "prior": f32(lay.prior), "pilots": f32(lay.pilot_amp * lay.pilot_signs),
            "folded": lay.folded.astype(np.int64), "fold_amp": f32(lay.fold_amp), "dct": f32(dct_matrix(res)),
            "prior_rest": np.array(rest, np.float32)}


def graph_feeds(snapshot: np.ndarray, res: int, channels: int, codec: str = formats.PRINT_CODEC) -> dict:
    """All inputs of the restore graph for a capture (380, 380, 3) uint8 RGB of (3, channels, res, res)
    planes under print codec `codec`."""
    n = formats.SNAPSHOT_SIZE
    if snapshot.shape != (n, n, 3) or snapshot.dtype != np.uint8:
        raise ValueError(f"a print capture is ({n}, {n}, 3) uint8 RGB, got {snapshot.shape} {snapshot.dtype}")
    return {"snapshot": snapshot_nchw(snapshot), **layout_feeds(print_layout(res, channels, codec))}


def reading_of(reading: np.ndarray) -> Reading:
    """The graph's `reading` output (3,) -> `print_read.Reading`."""
    gain, noise, rmse = (float(v) for v in np.asarray(reading, np.float64).ravel()[:3])
    return Reading(gain, noise, rmse)


@lru_cache(maxsize=16)
def layout_npz(codec: str, res: int, channels: int) -> bytes:
    """The layout inputs of (3, channels, res, res) planes under print codec `codec` as a numpy .npz file (one
    array per name of `LAYOUT_INPUTS`, in the graph's dtypes): what `snapshot3d serve` hands a client that
    restores on its own. ValueError for a codec or plane size the print medium does not carry."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **layout_feeds(print_layout(res, channels, codec)))
    return buf.getvalue()
