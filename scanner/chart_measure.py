"""Measurements on a rectified calibration chart (`scanner.chart`), numpy and OpenCV only.

Input everywhere: the rectified, colour-corrected snapshot square that `scan` gives, (380, 380, 3) uint8
sRGB RGB; the reference is `chart.chart_snapshot()`. Frequencies are in cycles per snapshot pixel, noise
in 8-bit sRGB code values (std) or in [0, 1]^2 units (power per band coefficient)."""
from __future__ import annotations

import cv2
import numpy as np

from snapshot3d.codecs import bands
from snapshot3d.codecs.print_carriers import PRINT_BANDS

from . import chart

__all__ = ["edge_mtf", "mtf50", "linearise", "chart_match", "measure_mtf", "measure_noise", "measure_tone", "measure_bands",
           "measure_misregistration", "measure_chart", "srgb_to_linear"]

_BIN = 0.25   # ESF bin width (snapshot pixels): 4x oversampling


def srgb_to_linear(codes: np.ndarray) -> np.ndarray:
    """sRGB codes in [0, 255] (uint8 or float, any shape) -> float64 linear in [0, 1]."""
    x = np.asarray(codes, np.float64) / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _luma(img: np.ndarray) -> np.ndarray:
    return srgb_to_linear(img) @ np.array([0.2126, 0.7152, 0.0722])


def edge_mtf(roi: np.ndarray, vertical: bool) -> tuple[np.ndarray, np.ndarray]:
    """Slanted-edge MTF (ISO 12233 style) of a window (h, w) float linear luma holding one straight edge;
    vertical: the edge runs along the rows' direction (profiles along x). Returns (frequencies, mtf), both
    (M,), frequencies in cycles per pixel up to 1."""
    a = roi if vertical else roi.T
    rows, cols = a.shape
    d = np.abs(np.diff(a, axis=1))
    x = np.arange(cols - 1) + 0.5
    centre = (d * x).sum(1) / np.maximum(d.sum(1), 1e-12)     # edge position per row (derivative centroid)
    y = np.arange(rows)
    slope, icpt = np.polyfit(y, centre, 1)
    for _ in range(2):   # refine with a window around the fitted edge
        wnd = np.abs(x[None, :] - (slope * y + icpt)[:, None]) < cols / 3
        dw = d * wnd
        centre = (dw * x).sum(1) / np.maximum(dw.sum(1), 1e-12)
        slope, icpt = np.polyfit(y, centre, 1)
    xx = np.arange(cols)[None, :] - (slope * y + icpt)[:, None]
    dist = (xx * np.cos(np.arctan(slope))).ravel()
    half = cols / 2 - 2
    nb = int(2 * half / _BIN)
    idx = np.floor((dist + half) / _BIN).astype(int)
    ok = (idx >= 0) & (idx < nb)
    cnt = np.bincount(idx[ok], minlength=nb)
    s = np.bincount(idx[ok], weights=a.ravel()[ok], minlength=nb)
    have = cnt > 0
    centres = np.arange(nb)
    esf = np.interp(centres, centres[have], s[have] / cnt[have])
    lsf = np.diff(esf)
    lsf *= np.hamming(len(lsf))
    spec = np.abs(np.fft.rfft(lsf, n=4 * len(lsf)))
    freq = np.fft.rfftfreq(4 * len(lsf), d=_BIN)
    mtf = spec / max(spec[0], 1e-12)
    mtf /= np.maximum(np.sinc(freq * _BIN), 0.2)   # the finite difference's own response
    keep = freq <= 1.0
    return freq[keep], mtf[keep]


def mtf50(freq: np.ndarray, mtf: np.ndarray) -> float:
    """The first frequency where the MTF falls to 0.5 (linear interpolation); the last frequency if never."""
    below = np.nonzero(mtf < 0.5)[0]
    if len(below) == 0:
        return float(freq[-1])
    i = int(below[0])
    if i == 0:
        return float(freq[0])
    f0, f1, m0, m1 = freq[i - 1], freq[i], mtf[i - 1], mtf[i]
    return float(f0 + (m0 - 0.5) * (f1 - f0) / max(m0 - m1, 1e-12))


def linearise(img: np.ndarray, tone_curve) -> np.ndarray:
    """(h, w, 3) uint8 codes -> float64 linear luma of the codes the printer was sent: the measured tone curve
    ([[sent, read], ...], `measure_tone`) inverted, then sRGB decoded (ISO 12233's OECF step)."""
    curve = np.asarray(tone_curve, np.float64)
    read = np.maximum.accumulate(curve[:, 1]) + np.arange(len(curve)) * 1e-6   # increasing, for interp
    lut = np.interp(np.arange(256), read, curve[:, 0])
    return srgb_to_linear(np.clip(lut[img], 0.0, 255.0)) @ np.array([0.2126, 0.7152, 0.0722])


def measure_mtf(img: np.ndarray, tone_curve=None, linear: np.ndarray | None = None) -> dict:
    """MTF50 (cycles per snapshot pixel) of the chart's slanted edges: of the mean MTF over the near-vertical
    edges (`mtf50_x`, resolution along x), over the near-horizontal ones (`mtf50_y`), and over all (`mtf50`);
    and that mean curve sampled at 0.05 cycles per pixel steps. The edges are measured in `linear` when given,
    (380, 380, 3) float linear RGB of the photo at the snapshot's pixels (`calibrate.photo_linear`: the light
    the camera saw, where its blur acted); else in `img` linearised through `tone_curve` (`measure_tone`), or
    taken as sRGB without one. The mean curve, not a median of the edges' MTF50s: one edge's MTF50 moves by
    up to 0.1 with the halftone's texture in its window, the mean of eight curves far less."""
    if linear is not None:
        lum = np.asarray(linear, np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    else:
        lum = _luma(img) if tone_curve is None else linearise(img, tone_curve)
    by_dir = {True: [], False: []}
    grid = np.arange(0.0, 0.75, 0.05)
    for x0, y0, x1, y1, vertical in chart.EDGE_ROIS:
        f, m = edge_mtf(lum[y0:y1, x0:x1], vertical)
        by_dir[vertical].append(m)
    mean = np.mean(by_dir[True] + by_dir[False], 0)
    return {"mtf50": mtf50(f, mean), "mtf50_x": mtf50(f, np.mean(by_dir[True], 0)),
            "mtf50_y": mtf50(f, np.mean(by_dir[False], 0)),
            "mtf_curve": [[round(float(g), 3), round(float(v), 4)] for g, v in zip(grid, np.interp(grid, f, mean))]}


def _inner(box, margin: int = 6):
    x0, y0, x1, y1 = box
    return slice(y0 + margin, y1 - margin), slice(x0 + margin, x1 - margin)


def measure_noise(img: np.ndarray) -> dict:
    """Noise of the flat grey patches: per patch (chart.PATCH_LEVELS) the std in 8-bit codes left after a
    plane is fitted away (per channel, mean over channels), their mean `noise_std`; and the colour error
    left after the scan's correction, the RMS of the patches' means against their printed codes."""
    stds, errs = [], []
    for box, level in zip(chart.PATCH_BOXES, chart.PATCH_LEVELS):
        ys, xs = _inner(box)
        win = img[ys, xs].astype(np.float64)
        h, w = win.shape[:2]
        gy, gx = np.mgrid[0:h, 0:w]
        A = np.stack([np.ones(h * w), gx.ravel(), gy.ravel()], 1)
        flat = win.reshape(-1, 3)
        res = flat - A @ np.linalg.lstsq(A, flat, rcond=None)[0]
        stds.append(float(np.mean(res.std(0))))
        errs.append(flat.mean(0) - level)
    errs = np.array(errs)
    return {"noise_std": float(np.mean(stds)), "noise_std_per_level": {str(lv): round(s, 3) for lv, s in
                                                                        zip(chart.PATCH_LEVELS, stds)},
            "colour_rmse": float(np.sqrt(np.mean(errs ** 2)))}


def measure_tone(img: np.ndarray, points: int = 17) -> dict:
    """The tone curve from the ramp: `tone_curve` [[printed code, read code], ...] at `points` codes (grey,
    mean over channels and the ramp's inner rows), and its RMS error against the identity (`tone_rmse`)."""
    x0, y0, x1, y1 = chart.RAMP_BOX
    prof = img[y0 + 6:y1 - 6, x0:x1].astype(np.float64).mean((0, 2))
    codes = (np.arange(x1 - x0) + 0.5) / (x1 - x0) * 255.0
    want = np.linspace(0, 255, points)
    cols = np.clip(np.round(want / 255.0 * (x1 - x0) - 0.5).astype(int), 3, x1 - x0 - 4)
    got = np.array([prof[c - 3:c + 4].mean() for c in cols])
    sent = np.array([codes[c - 3:c + 4].mean() for c in cols])
    return {"tone_curve": [[round(float(s), 1), round(float(g), 1)] for s, g in zip(sent, got)],
            "tone_rmse": float(np.sqrt(np.mean((got - sent) ** 2)))}


def _median_power(maps: list) -> float:
    """Power per coefficient of residual maps (a band's (h, w) maps, one per carrier square), robust to a few
    strong spatial frequencies: the median of their periodograms over every frequency, over ln 2 (a periodogram
    value of white Gaussian noise is exponential, its median ln 2 times its mean). A halftone's moire puts its
    power in a few narrow peaks whose place and height change with the pose; a mean over coefficients counts
    them fully, this median does not."""
    pw = np.concatenate([(np.abs(np.fft.fft2(m)) ** 2 / m.size).ravel() for m in maps])
    return float(np.median(pw) / np.log(2.0))


def measure_bands(img: np.ndarray) -> dict:
    """The print channel per print-codec band (`PRINT_BANDS`) over the carrier squares, in `print_channel`'s
    terms: every coefficient weighed as the codec's matched filters weigh it (`print_carriers.filters`: a
    carrier's chip w goes as 1/sqrt(n) and its filter q as w/n, n the print noise model `band_noise` of the
    capture there; so a gain counts each coefficient by q w, 1/n^2, and a noise power by q^2, 1/n^3).
    Per band: `gain`, the weighted least-squares ratio of the capture's coefficients to the chart's;
    `squares`, the same ratio in each carrier square (`chart.CARRIER_BOXES`; a tilted or unevenly focused photo
    reads them apart);
    `noise`, the power per coefficient left ([0, 1]^2 units, unweighted); `unit`, the power left relative to
    the noise model (what `print_read.band_response` calls the noise). Over all bands: `print_channel`, the
    `print_channel.ChannelModel` fields (`gain`, `unit`: one reading over all bands' chips, as a carrier's),
    and `channel`, unweighted as before `print_channel` was added (`gain`: one least-squares ratio over all
    bands' coefficients; `unit`: the power per coefficient left, [0, 1]^2 units, robust to the halftone's moire
    (`_median_power`; `unit_mean`: the plain mean, what `unit` was before))."""
    from snapshot3d.codecs.print_carriers import band_noise

    ref = chart.chart_snapshot()
    model = band_noise(img / 255.0)
    parts = {b: [] for b in PRINT_BANDS}   # (capture, chart, noise model) coefficients of each square
    for x0, y0, x1, y1 in chart.CARRIER_BOXES:
        c = bands.analyse(img[y0:y1, x0:x1] / 255.0)
        r = bands.analyse(ref[y0:y1, x0:x1] / 255.0)
        for b in PRINT_BANDS:
            f = 2 ** int(b[-3])   # the square's place in the band's whole-square map (to a cell: the model is smooth)
            h, w = c[b].shape
            parts[b].append((c[b], r[b], model[b][y0 // f:y0 // f + h, x0 // f:x0 // f + w]))
    num, den, gain, sq, out = {}, {}, {}, {}, {}
    for b, ps in parts.items():
        nums = [float(np.sum(c * r / n ** 2)) for c, r, n in ps]   # per carrier square
        dens = [float(np.sum(r * r / n ** 2)) for _, r, n in ps]
        num[b], den[b] = sum(nums), sum(dens)
        gain[b] = num[b] / max(den[b], 1e-30)
        sq[b] = [x / max(y, 1e-30) for x, y in zip(nums, dens)]
    total_g = sum(num.values()) / max(sum(den.values()), 1e-30)
    plain_g = sum(float(np.sum(c * r)) for ps in parts.values() for c, r, _ in ps) / max(
        sum(float(np.sum(r * r)) for ps in parts.values() for _, r, _ in ps), 1e-30)
    res2 = cnt = rel = var = robust = 0.0
    for b, ps in parts.items():
        e = PRINT_BANDS[b]
        r2 = [(c - gain[b] * r) ** 2 for c, r, _ in ps]
        rb = sum(float(np.sum(x / n ** 3)) for x, (_, _, n) in zip(r2, ps))
        vb = sum(float(np.sum(1.0 / n ** 2)) for _, _, n in ps)
        nb = sum(x.size for x in r2)
        pg = sum(float(np.sum(c * r)) for c, r, _ in ps) / max(sum(float(np.sum(r * r)) for _, r, _ in ps), 1e-30)
        raw = sum(float(np.sum((c - pg * r) ** 2)) for c, r, _ in ps)   # unweighted, as `noise` always was
        out[b] = {"gain": round(gain[b], 4), "noise": float(f"{raw / nb:.4g}"), "unit": float(f"{rb / vb:.4g}"),
                  "squares": [round(x, 4) for x in sq[b]]}
        rel += e * sum(float(np.sum((c - total_g * r) ** 2 / n ** 3)) for c, r, n in ps)
        var += e * vb
        res2 += raw
        cnt += nb
        robust += nb * _median_power([c - plain_g * r for c, r, _ in ps])
    return {"bands": out, "channel": {"gain": round(plain_g, 4), "unit": float(f"{robust / cnt:.4g}"),
                                      "unit_mean": float(f"{res2 / cnt:.4g}")},
            "print_channel": {"gain": round(total_g, 4), "unit": float(f"{rel / var:.4g}")}}


def measure_misregistration(img: np.ndarray) -> dict:
    """Residual misregistration: the shift (dx, dy) in snapshot pixels of each carrier square against the
    chart (phase correlation), and the largest of their lengths (`misregistration_px`)."""
    ref = chart.chart_snapshot()
    shifts = []
    for x0, y0, x1, y1 in chart.CARRIER_BOXES:
        a = _luma(img[y0:y1, x0:x1]).astype(np.float32)
        b = _luma(ref[y0:y1, x0:x1]).astype(np.float32)
        win = cv2.createHanningWindow(a.shape[::-1], cv2.CV_32F)
        (dx, dy), _ = cv2.phaseCorrelate(b, a, win)
        shifts.append([round(float(dx), 3), round(float(dy), 3)])
    return {"shifts_px": shifts, "misregistration_px": float(max(np.hypot(*s) for s in shifts))}


def measure_chart(img: np.ndarray, linear: np.ndarray | None = None) -> dict:
    """All of the above on a rectified chart (380, 380, 3) uint8 sRGB RGB, one dict; `linear`: the photo's
    linear light at the snapshot's pixels for the MTF (`measure_mtf`)."""
    n = chart.N
    if img.shape != (n, n, 3) or img.dtype != np.uint8:
        raise ValueError(f"expected ({n}, {n}, 3) uint8 RGB, got {img.shape} {img.dtype}")
    out = measure_tone(img)
    for f in (measure_noise, measure_bands, measure_misregistration):
        out.update(f(img))
    out.update(measure_mtf(img, out["tone_curve"], linear))
    return out


def chart_match(img: np.ndarray) -> float:
    """Correlation in [-1, 1] of an image's carrier squares with the chart's: about 1 for a capture of the
    chart, about 0 for anything else (how `calibrate` tells a chart whose QR code is unreadable)."""
    ref = chart.chart_snapshot().astype(np.float64)
    a = np.concatenate([img[y0:y1, x0:x1].astype(np.float64).ravel() for x0, y0, x1, y1 in chart.CARRIER_BOXES])
    b = np.concatenate([ref[y0:y1, x0:x1].ravel() for x0, y0, x1, y1 in chart.CARRIER_BOXES])
    a, b = a - a.mean(), b - b.mean()
    return float(a @ b / max(np.sqrt((a @ a) * (b @ b)), 1e-12))
