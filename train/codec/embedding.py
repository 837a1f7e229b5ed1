"""A scene's snapshot in a host, per medium: `EMBEDDERS` and `STRENGTH_FINDERS` hold each medium's
function (medium name -> function; the media themselves are `snapshot3d.codecs.media`'s). `print`: the
designed carriers (numpy); `file`: the invertible network (torch, imported when used).

Layouts: host (380, 380, 3) float RGB in [0, 1]; snapshot (380, 380, 3) uint8 RGB."""
from __future__ import annotations

import math

import numpy as np

from snapshot3d import formats
from snapshot3d.codecs import print_embed, print_source
from snapshot3d.codecs.media import MEDIA
from snapshot3d.errors import UserError
from snapshot3d.metrics import psnr
from snapshot3d.scanner.pixelmeta import mark
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import Scene

__all__ = ["check_planes_for", "snapshot_for", "marked_host", "strength_for", "EMBEDDERS", "STRENGTH_FINDERS",
           "STRENGTHS"]

STRENGTHS = (0.05, 10.0)
"""the embedding strengths `embed --strength` takes, and `--host-psnr` chooses among"""


def check_planes_for(medium: str, scene: Scene) -> None:
    """UserError unless the medium's codec carries the scene's planes."""
    MEDIA[medium].check_planes(scene.channels, scene.resolution)


def marked_host(host: np.ndarray, scene: Scene, strength: float = 1.0) -> np.ndarray:
    """A file snapshot's host: `host` ((380, 380, 3) float RGB in [0, 1]) marked with the scene's metadata
    (`scanner.pixelmeta`, 8-bit), float32 in [0, 1]."""
    meta = scene_meta(scene, formats.FILE_CODEC, strength)
    return mark(np.clip(np.asarray(host) * 255 + 0.5, 0, 255).astype(np.uint8), meta).astype(np.float32) / 255.0


def _print_snapshot(host: np.ndarray, scene: Scene, strength: float, refine: int, show_progress: bool) -> np.ndarray:
    return print_embed.embed(host, scene.planes(), print_source.HOST_PSNR - 20 * np.log10(strength))


def _file_snapshot(host: np.ndarray, scene: Scene, strength: float, refine: int, show_progress: bool) -> np.ndarray:
    from .hinet import load_codec
    from .refine import snapshot_of
    host = marked_host(host, scene, strength)
    return snapshot_of(load_codec()[0], host, scene.planes(), refine, strength, show_progress=show_progress)


EMBEDDERS = {"print": _print_snapshot, "file": _file_snapshot}
"""medium name -> (host, scene, strength, refine, show_progress) -> snapshot"""


def snapshot_for(medium: str, host: np.ndarray, scene: Scene, strength: float = 1.0, refine: int = 0,
                 show_progress: bool = False) -> np.ndarray:
    """The snapshot (380, 380, 3) uint8 RGB of `scene` in `host` ((380, 380, 3) float RGB in [0, 1]) for a
    medium: `print` (the designed carriers, at the print host fidelity less 20 log10(strength) dB) or `file`
    (the invertible network, refined `refine` steps). A `file` snapshot's host is first marked with its
    metadata (`scanner.pixelmeta`), so that a shared copy stripped of its text still restores; a `print`
    snapshot's metadata travels in the sheet's QR code (and the file's text)."""
    return EMBEDDERS[medium](host, scene, strength, refine, show_progress)


def _floor_3(x: float) -> float:
    """`x` > 0 rounded down to three significant digits (a strength the metadata's text carries exactly)."""
    e = math.floor(math.log10(x)) - 2
    return float(f"{math.floor(x / 10 ** e + 1e-9) * 10 ** e:.3g}")


def _print_strength(host: np.ndarray, scene: Scene, host_psnr: float, tol_db: float, iters: int) -> float:
    return _floor_3(min(max(10 ** ((print_source.HOST_PSNR - host_psnr) / 20), STRENGTHS[0]), STRENGTHS[1]))


def _file_strength(host: np.ndarray, scene: Scene, host_psnr: float, tol_db: float, iters: int) -> float:
    from .hinet import embed_planes, load_codec

    net, host8 = load_codec()[0], np.clip(np.asarray(host) * 255 + 0.5, 0, 255).astype(np.uint8)

    def over(x: float) -> float:   # dB kept over the target at strength exp(x); falls as x grows
        s = _floor_3(math.exp(x))
        return psnr(embed_planes(net, marked_host(host, scene, s), scene.planes(), s) / 255.0, host8 / 255.0) - host_psnr

    x_min, x_max = math.log(STRENGTHS[0]), math.log(STRENGTHS[1])
    hi, f_hi = 0.0, over(0.0)                   # strength 1, then halve or double it to bracket the target
    lo, f_lo = hi, f_hi
    while f_lo < 0 and lo > x_min:
        hi, f_hi = lo, f_lo
        lo = max(lo - math.log(2), x_min)
        f_lo = over(lo)
    if f_lo < 0:
        raise UserError(f"the file codec keeps at most {host_psnr + f_lo:.1f} dB of this host (at --strength "
                        f"{STRENGTHS[0]:g}), not {host_psnr:g}")
    while f_hi >= 0 and hi < x_max:
        lo, f_lo = hi, f_hi
        hi = min(hi + math.log(2), x_max)
        f_hi = over(hi)
    if f_hi >= 0:
        return STRENGTHS[1]
    side = 0
    for _ in range(iters):
        if f_lo < tol_db:
            break
        x = hi - f_hi * (hi - lo) / (f_hi - f_lo)
        f = over(x)
        if f >= 0:
            lo, f_lo, f_hi = x, f, f_hi / 2 if side == -1 else f_hi
            side = -1
        else:
            hi, f_hi, f_lo = x, f, f_lo / 2 if side == 1 else f_lo
            side = 1
    return _floor_3(math.exp(lo))


STRENGTH_FINDERS = {"print": _print_strength, "file": _file_strength}
"""medium name -> (host, scene, host_psnr, tol_db, iters) -> strength"""


def strength_for(medium: str, host: np.ndarray, scene: Scene, host_psnr: float, tol_db: float = 0.05,
                 iters: int = 8) -> float:
    """The embedding strength, in [0.05, 10] and three significant digits, at which the snapshot of `scene` in
    `host` ((380, 380, 3) float RGB in [0, 1]) keeps `host_psnr` dB of its host: `print`, exactly (its carriers
    are scaled to a host fidelity); `file`, the largest at which the network's snapshot (marked; the
    refinement holds its host fidelity) keeps it to within `tol_db` over, found by regula falsi (Illinois)
    on the host PSNR against log strength. UserError when no strength keeps it."""
    return STRENGTH_FINDERS[medium](host, scene, host_psnr, tol_db, iters)
