"""Writing the `print` medium's carriers into a host (numpy; torch-free).

The embedder knows the host, so it cancels the host's own projection on each carrier (improved spread
spectrum, Malvar and Florencio 2003): the decoder sees the carrier's value plus channel noise, not the
host. How much of it to cancel is weighed per host (`cancel_share`). Clipping to [0, 1] and 8-bit rounding
are corrected by a few projection rounds (`embed`).

Layouts: host (380, 380, 3) float RGB in [0, 1]; planes (3, C, R, R) float in [-1, 1]; snapshot
(380, 380, 3) uint8 RGB; carrier values (N,) float in `print_carriers` order (pilots first).
"""
from __future__ import annotations

import numpy as np

from snapshot3d import formats

from . import bands, print_fold
from .print_carriers import PrintLayout, filters, flat, print_layout, unflat
from .print_source import HOST_PSNR, plane_dct

__all__ = ["carrier_values", "cancel_share", "embed", "embed_values", "READ_NOISE"]

READ_NOISE = 0.003
"""channel noise per carrier reading (at the payload's design scale) the host cancellation is weighed
against (`moderate` photos)"""


def carrier_values(lay: PrintLayout, planes: np.ndarray, strength: float = 1.0) -> np.ndarray:
    """planes (3, C, R, R) -> what each carrier must read (N,): pilots, scaled DCT coefficients, then the
    folded coefficients' helix carriers (cos, then sin)."""
    coef = plane_dct(planes)[lay.coef]
    cos, sin = print_fold.helix(coef[lay.folded] / np.sqrt(lay.prior[lay.folded]))
    return strength * np.concatenate([lay.pilot_amp * lay.pilot_signs, coef * lay.scale,
                                      lay.fold_amp * cos, lay.fold_amp * sin])


def cancel_share(host: np.ndarray, lay: PrintLayout, host_psnr: float) -> float:
    """How much of the host's own projection on the carriers to cancel, lambda in [0, 1]: cancelling costs
    host fidelity (lambda^2 times the projections' energy), leaving it costs the reader (1 - lambda)^2
    times it as interference; the share that gives the best reading SNR for this host at this fidelity,
    against READ_NOISE. A smooth host is cancelled wholly, a busy one in part."""
    w, q = filters(lay, np.asarray(host, np.float64))
    own = np.einsum("nk,nk->n", flat(bands.analyse(host), lay.bands)[lay.chips], q)
    inter = float(np.mean(own ** 2))                       # per carrier
    budget = 10 ** (-host_psnr / 10) * host.size / lay.carriers
    lam = np.linspace(0.0, 1.0, 41)
    payload = budget - lam ** 2 * inter
    snr = np.where(payload > 0, payload / (READ_NOISE + (1 - lam) ** 2 * inter), -1.0)
    return float(lam[int(np.argmax(snr))])


def embed(host: np.ndarray, planes: np.ndarray, host_psnr: float = HOST_PSNR, rounds: int = 4,
          cancel: float | None = None, with_payload: bool = False, codec: str = formats.PRINT_CODEC):
    """host (380, 380, 3) float RGB in [0, 1], planes (3, C, R, R) in [-1, 1] -> snapshot (380, 380, 3)
    uint8 RGB at `host_psnr` dB from the host (the payload's power is scaled to it; the pilots tell the
    decoder the scale) whose every carrier reads its value plus what is left of the host's own projection:
    `cancel` of it is cancelled (None: `cancel_share` decides for this host), and clipping and rounding
    are corrected by `rounds` projections. `with_payload`: also the payload pattern alone (380, 380, 3)
    float32, the carriers times their values with no host (what the restore front-end learns to find).
    `codec`: the print codec id whose carriers to write."""
    _, c, r, _ = planes.shape
    lay = print_layout(r, c, codec)
    unit = carrier_values(lay, planes)
    snap, scaled = embed_values(host, lay, unit, host_psnr, rounds, cancel)
    if not with_payload:
        return snap
    w, _ = filters(lay, snap / 255.0)
    coeffs = {b: np.zeros_like(v) for b, v in bands.analyse(snap / 255.0).items()}
    vec = flat(coeffs, lay.bands)
    vec[lay.chips] = w * scaled[:, None]
    return snap, bands.synthesise(unflat(vec, coeffs, lay.bands)).astype(np.float32)


def embed_values(host: np.ndarray, lay: PrintLayout, unit: np.ndarray, host_psnr: float = HOST_PSNR,
                 rounds: int = 4, cancel: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Any carrier values (N,) (pilots first) written into host (380, 380, 3) float RGB in [0, 1] at
    `host_psnr` dB (see `embed`): the snapshot (380, 380, 3) uint8 RGB and the values as scaled (N,)."""
    n = formats.SNAPSHOT_SIZE
    if host.shape != (n, n, 3):
        raise ValueError(f"host must be ({n}, {n}, 3) RGB, got {host.shape}")
    host = np.asarray(host, np.float64)
    cancel = cancel_share(host, lay, host_psnr) if cancel is None else cancel
    host8 = np.round(np.clip(host, 0, 1) * 255.0) / 255.0
    want = 10 ** (-host_psnr / 10)
    base = 0.0   # without cancelling, an empty payload costs nothing but rounding
    if cancel > 0:
        base = float(np.mean((_embed_scaled(lay, host, 0.0 * unit, rounds, cancel) / 255.0 - host8) ** 2))
        if base >= want:
            raise ValueError(f"cancelling the host alone costs more than {host_psnr} dB of host fidelity")
    scale = np.sqrt(want / max(float(np.mean(unit ** 2)) * len(unit) / host8.size, 1e-12))   # energy is preserved
    for _ in range(2):   # the payload's scale that lands on the host fidelity asked for: mse = base + s^2 P
        snap = _embed_scaled(lay, host, unit * scale, rounds, cancel)
        mse = float(np.mean((snap / 255.0 - host8) ** 2))
        scale *= np.sqrt((want - base) / max(mse - base, 1e-12))
    return _embed_scaled(lay, host, unit * scale, rounds, cancel), unit * scale


def _embed_scaled(lay: PrintLayout, host: np.ndarray, target: np.ndarray, rounds: int, cancel: float) -> np.ndarray:
    img, own = host, None
    for _ in range(rounds + 1):
        w, q = filters(lay, img)   # as the decoder will see them in this very image
        coeffs = bands.analyse(img)
        vec = flat(coeffs, lay.bands)
        read = np.einsum("nk,nk->n", vec[lay.chips], q)
        own = read if own is None else own   # the host's own projection, measured once
        vec[lay.chips] += w * (target + (1.0 - cancel) * own - read)[:, None]
        img = np.round(np.clip(bands.synthesise(unflat(vec, coeffs, lay.bands)), 0.0, 1.0) * 255.0) / 255.0
    return (img * 255.0 + 0.5).astype(np.uint8)
