"""The channel a decode went through, as the print codec's pilots measure it (issue 38 item 4): gain and
noise in `print_channel`'s terms, the pilots' effective SNR, the nearest `simulate` preset and one line of
advice on what would help the next photo most. numpy only, on the rectified capture the restore read.

The pilots are read here with the designed matched filters (`print_read.despread(..., combine=False)`'s,
as `print_channel.measure` reads them), per band as well as over all bands, so that
- `gain` is the pilots' reading over their designed value (`ChannelModel.gain` without the digital copy's
  own gain, about 1) and `noise` the noise power per carrier of unit relative noise power (`ChannelModel.unit`);
- `band_gain` says which bands the capture kept: blur takes the finest (Y1) before the coarser (Y2);
- `snr_db` is the pilots' SNR through the receiver that restored the planes (the bands combined as the
  pilots say: `print_read.band_weights`), 10 log10((gain * amplitude)^2 / noise) of the restore's `Reading`.

The nearest preset is the one whose reference (`CHANNEL_REFERENCE`: mean and spread of the features over
simulated photos, `snapshot3d bench decode-channel --reference`) lies nearest in units of its spread (a
diagonal Gaussian's negative log-likelihood, as `scanner.calibrate.nearest_preset`). A photo whose gain
lies above mild's mean by more than mild's spread is "better than mild"."""
from __future__ import annotations

import math
import time
from functools import lru_cache

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.codecs import bands
from snapshot3d.codecs.media import CODEC_MEDIUM
from snapshot3d.codecs.print_carriers import PILOTS, PRINT_BANDS, PRINT_NOISE, flat, print_layout, srgb_slope
from snapshot3d.codecs.print_read import band_fit, per_band

__all__ = ["CHANNEL_REFERENCE", "FEATURES", "BLUR_FIT", "STEADY_PX", "STEADY_SIGMA_PX", "pilot_channel",
           "nearest_preset", "blur_px", "advice", "channel_report", "px_per_pixel"]

FEATURES = ("gain",)
"""the logs the nearest preset is chosen by. Over the reference photos (leave one out) the pilots' gain alone
names the preset right in 88 % of them; adding the noise (82 %) or the finest bands' gain over the next
level's (82 %) does worse: within a preset the pilots' noise tracks the blur, not the sensor's noise"""
CHANNEL_REFERENCE = {
    # (mean, std) of log(gain), log(noise) over simulated photos of spot-print and lego-print-auto (16x4) in the
    # hosts coffee and chelsea, seeds 100-105 (66 of 72 scanned): `snapshot3d bench decode-channel --reference`
    "mild": ((-0.238, 0.137), (1.797, 0.497)),
    "moderate": ((-0.591, 0.208), (2.043, 0.502)),
    "severe": ((-1.738, 0.555), (2.552, 0.462)),
}
BLUR_FIT = (-0.995, -0.921)
"""log(blur in snapshot pixels + 0.05) = a + b log(gain), least squares over the same photos (the simulator's
defocus radius plus motion length over photo pixels per snapshot pixel; RMS error 0.48, correlation 0.80)"""
STEADY_PX = 2.0
"""camera blur (photo pixels) up to which a photo counts as steady and focused: `mild`'s defocus plus motion"""
STEADY_SIGMA_PX = 0.9
"""the photo check's edge blur (a Gaussian's sigma, photo pixels) up to which a photo counts as steady and focused:
between `mild`'s most and `moderate`'s least on the reference photos (`bench decode-channel --reference`), where it
agrees with the simulator's defocus plus motion against STEADY_PX on 62 of 66 photos (the gain's `blur_px`: 53)"""


def _print_bands(cap: np.ndarray) -> tuple[dict, np.ndarray]:
    """`bands.analyse`'s bands of the print codec (`PRINT_BANDS`: luma levels 1 and 2, red-green level 2) of
    an image (380, 380, 3) float32 RGB in [0, 1], in float32 and nothing else (an eighth of its time); and
    the image's grey (mean of R, G, B: (380, 380) float32)."""
    y, rg = np.moveaxis(cap @ bands.OPPONENT[:2].T.astype(np.float32), 2, 0)
    ll1, (lh1, hl1, _) = bands.haar(y)
    _, (lh2, hl2, hh2) = bands.haar(ll1)
    _, (rlh2, rhl2, _) = bands.haar(bands.haar(rg)[0])
    return ({"Y2LH": lh2, "Y2HL": hl2, "Y2HH": hh2, "Y1LH": lh1, "Y1HL": hl1, "RG2LH": rlh2, "RG2HL": rhl2},
            y * np.float32(1 / math.sqrt(3.0)))


def _noise_pool(grey: np.ndarray) -> np.ndarray:
    """`print_carriers.noise_map(image, PRINT_BANDS)` from the image's grey (380, 380) float32 (the codec's
    bands are all of levels 1 and 2)."""
    n = formats.SNAPSHOT_SIZE
    blur = cv2.GaussianBlur(grey, (0, 0), 2.0)
    small = {lvl: cv2.resize(blur, (n // 2 ** lvl,) * 2, interpolation=cv2.INTER_AREA) for lvl in (1, 2)}
    maps = {lvl: PRINT_NOISE * np.minimum(srgb_slope(m.astype(np.float64)) ** 2, 100.0) for lvl, m in small.items()}
    return np.concatenate([maps[int(b[-3])].ravel() for b in PRINT_BANDS])


@lru_cache(maxsize=8)
def _pilot_bands(res: int, channels: int, codec: str) -> np.ndarray:
    """(PILOTS, K) int: the index in PRINT_BANDS of every pilot chip's band."""
    n = formats.SNAPSHOT_SIZE
    edges = np.cumsum([int(np.prod(bands.band_shape(b, n))) for b in PRINT_BANDS])
    return np.searchsorted(edges, print_layout(res, channels, codec).chips[:PILOTS], side="right")


def pilot_channel(snapshot: np.ndarray, res: int, channels: int, codec: str) -> dict:
    """The pilots of a capture (380, 380, 3) uint8 RGB of (3, channels, res, res) planes under print codec
    `codec`, read with the designed filters: {"gain", "noise" (unit), "band_gain": {band: gain}, "pilot_amp"}."""
    lay = print_layout(res, channels, codec)
    coeffs, grey = _print_bands(snapshot.astype(np.float32) / np.float32(255.0))
    p = slice(0, PILOTS)
    noise = _noise_pool(grey)[lay.chips[p]]
    w = lay.base[p] / np.sqrt(noise)
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    q = w / noise
    q /= np.einsum("nk,nk->n", q, w)[:, None]
    chips = flat(coeffs, PRINT_BANDS)[lay.chips[p]].astype(np.float64)
    band, nb = _pilot_bands(res, channels, codec), len(PRINT_BANDS)
    value = lay.pilot_amp * lay.pilot_signs
    g_band, _ = band_fit(per_band(band, q * chips, nb), per_band(band, q * w, nb) * value[:, None])
    read = np.einsum("nk,nk->n", chips, q) * lay.pilot_signs
    factor = np.einsum("nk,nk->n", q * q, noise)
    gain = max(float(np.mean(read)) / lay.pilot_amp, 1e-3)
    unit = max(float(np.mean((read - gain * lay.pilot_amp) ** 2 / factor)), 1e-14)
    return {"gain": gain, "noise": unit, "pilot_amp": float(lay.pilot_amp),
            "band_gain": {b: float(g) for b, g in zip(PRINT_BANDS, g_band)}}


def px_per_pixel(corners) -> float:
    """Photo pixels per snapshot pixel of a scan: the square root of the snapshot's area in the photo (corners
    (4, 2) photo pixels, in order around the square) over the snapshot's side."""
    x, y = np.asarray(corners, np.float64).T
    area = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
    return math.sqrt(area) / formats.SNAPSHOT_SIZE


def _features(m: dict) -> np.ndarray:
    return np.log(np.maximum([m[k] for k in FEATURES], 1e-14))


def nearest_preset(m: dict) -> tuple[str, dict]:
    """The preset whose reference lies nearest the pilots' measure (`pilot_channel`'s dict), or "better than
    mild" (a gain above mild's mean by more than its spread); and each preset's distance (negative
    log-likelihood, lower is nearer)."""
    x, k = _features(m), len(FEATURES)
    dist = {}
    for name, ref in CHANNEL_REFERENCE.items():
        mu, sd = np.array(ref[:k]).T
        dist[name] = float(0.5 * np.sum(((x - mu) / sd) ** 2) + np.sum(np.log(sd)))
    (g_mu, g_sd) = CHANNEL_REFERENCE["mild"][0]
    if x[0] > g_mu + g_sd:
        return "better than mild", dist
    return min(dist, key=dist.get), dist


def blur_px(gain: float, px_per_pixel: float) -> float:
    """The camera blur (photo pixels) the pilots' gain points to, for a snapshot `px_per_pixel` photo pixels
    per snapshot pixel (`BLUR_FIT`)."""
    a, b = BLUR_FIT
    return max(math.exp(a + b * math.log(max(gain, 1e-3))) - 0.05, 0.0) * px_per_pixel


def advice(m: dict, preset: str, px_per_pixel: float | None, edge_blur: float | None = None) -> str:
    """One line: what would help the next photo most. Over the reference photos the pilots' loss is blur in
    snapshot pixels: the camera's blur over the snapshot's size in the photo. When the camera's blur is more
    than a steady, focused phone's, a steadier, focused photo helps; else a closer one (more photo pixels per
    snapshot pixel). The camera's blur is the photo check's (`edge_blur`: the markers' edge sigma in snapshot
    pixels, times `px_per_pixel`, against STEADY_SIGMA_PX); where no edge was read, the one the pilots' gain
    points to (`blur_px` against STEADY_PX). The pilots' noise does not say "more light": it does not follow
    the sensor's noise (see FEATURES)."""
    head = f"this photo: like `{preset}`" if preset in CHANNEL_REFERENCE else f"this photo: {preset}"
    if px_per_pixel is None:
        return head.replace("this photo", "this snapshot file") + " (no photo to improve)"
    if preset == "better than mild":
        return head + "; nothing to improve"
    blurred = (edge_blur * px_per_pixel > STEADY_SIGMA_PX if edge_blur is not None
               else blur_px(m["gain"], px_per_pixel) > STEADY_PX)
    if blurred:
        return head + "; hold the phone steadier and let it focus (a sharper photo)"
    return head + "; hold the phone closer (let the sheet fill more of the frame)"


def channel_report(codec: str, snapshot: np.ndarray, planes: tuple, info: dict,
                   px_per_pixel: float | None = None, edge_blur: float | None = None) -> dict:
    """The `channel` block of a decode's report. `snapshot`: the capture the restore read (380, 380, 3) uint8
    RGB; `planes`: (res, channels); `info`: the restorer's (pilot_gain, pilot_noise for a print codec);
    `px_per_pixel`: photo pixels per snapshot pixel (None for a snapshot file); `edge_blur`: the photo check's
    blur (snapshot pixels; None where it read no edge). The file medium has no
    pilots: every value None, with the reason."""
    keys = ("gain", "noise", "snr_db", "band_gain", "nearest_preset", "preset_distance", "advice")
    if CODEC_MEDIUM.get(codec) != "print":
        return {"basis": None, **dict.fromkeys(keys), "ms": None,
                "reason": f"codec {codec} (file medium) carries no pilots to measure the channel with"}
    t0 = time.perf_counter()
    m = pilot_channel(snapshot, planes[0], planes[1], codec)
    name, dist = nearest_preset(m)
    amp, g, n = m["pilot_amp"], info.get("pilot_gain"), info.get("pilot_noise")
    snr = 10 * math.log10(max((g * amp) ** 2, 1e-30) / max(n, 1e-30)) if g is not None and n else None
    out = {"basis": "the print codec's 256 pilot carriers",
           "gain": round(m["gain"], 4), "noise": float(f"{m['noise']:.4g}"),
           "snr_db": None if snr is None else round(snr, 2),
           "band_gain": {b: round(v, 4) for b, v in m["band_gain"].items()},
           "nearest_preset": name, "preset_distance": {k: round(v, 3) for k, v in dist.items()},
           "advice": advice(m, name, px_per_pixel, edge_blur), "reason": None}
    out["ms"] = round((time.perf_counter() - t0) * 1e3, 2)
    return out
