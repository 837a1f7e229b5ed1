"""Slanted-edge MTF, noise and tone of a photo of a printed board (`bench channel --real`), numpy + OpenCV.

- edges (`edge_samples`): each side of each black quad (`board_register.find_quads`), on the stretches where
  the photo shows deep black behind it and clear white before it, its line refined by the gradient's centroid;
  every photo pixel within the window gives one (signed distance, value) sample, white side positive. The
  photo is not resampled.
- MTF (`esf_mtf`, a variant of `scanner.chart_measure.edge_mtf` that takes (distance, value) samples, so that
  many edges and raw pixels can be pooled: the same binning at 1/4 px, derivative, 4x zero-padded FFT, DC
  normalisation and finite-difference correction, but a Tukey window in place of the Hamming one because the
  windows here are a few pixels wide). The ESF is pooled over all edges, each normalised by its plateaus:
  MTF50 in cycles per photo pixel (`mtf50_px`) and, through the board's homography, per snapshot pixel
  (`mtf50_snap`: the photo's own MTF in the sheet's units, before any rectification; `calibrate`'s mtf50 is
  measured after the scan's resampling to 380 x 380 and tops out near 0.58, so the two do not compare).
- noise: robust std (1.4826 MAD) of the 8-bit codes about the ESF on each plateau, per channel, mean of
  channels (`noise_white`, `noise_black`); tone: the plateaus' grey codes (`black`, `white`), `contrast` =
  linear black / white (ink black, flare and exposure together), `snr` = (white - black) / noise_white;
  `overshoot`: how far the pooled ESF rises above its white plateau (a camera's sharpening).

Sheet geometry (`mtf50_snap`): the simulated sheets carry the board centred on a sheet-sized canvas
(`board_register.sheet_canvas`); a board unit is then a known number of snapshot pixels. For a real photo the
same number is assumed: the board fills the frame the way it would fill a sheet. Photos that match no known
board are measured quad by quad and have no `mtf50_snap`."""
from __future__ import annotations

import cv2
import numpy as np

from snapshot3d.errors import UserError
from snapshot3d.scanner.chart_measure import mtf50, srgb_to_linear

from .board_register import KNOWN_BOARDS, BoardSpec, board_quads, find_quads, register_board, snap_per_unit

__all__ = ["edge_samples", "esf_mtf", "measure_photo", "MIN_EDGES"]

_BIN = 0.25                      # ESF bin (photo or snapshot pixels), as chart_measure
_LUMA = np.array([0.0722, 0.7152, 0.2126])   # BGR order


def _grad_centroid(d, t, g, half, L):
    """Refine an edge line d = c0 + c1 * t from the gradient's centroid across it in 4 slices along t."""
    ts, cs = [], []
    for a, b in zip(np.linspace(0.12, 0.88, 5)[:-1] * L, np.linspace(0.12, 0.88, 5)[1:] * L):
        m = (t >= a) & (t < b) & (np.abs(d) < half)
        w = np.clip(g[m], 0, None)
        if w.sum() > 0:
            ts.append((a + b) / 2)
            cs.append(float((w * d[m]).sum() / w.sum()))
    if len(ts) < 2:
        return 0.0, 0.0
    c1, c0 = np.polyfit(ts, cs, 1)
    return float(c0), float(c1)


def edge_samples(img: np.ndarray, quad: np.ndarray, full: bool | None = None, white: float = 0.15) -> list[dict]:
    """For each side of one black quad ((4, 2) photo px, clockwise), the photo pixels across it: dict with
    `d` (signed distance to the refined edge line, photo px, white side positive), `lin` (linear luma),
    `codes` (N, 3) BGR codes, `half` (window half-width, px), `normal` (unit, outward), `mid` (photo px),
    `vertical` (the edge runs nearer the y axis). Only the stretches with deep black behind the edge are
    kept: for a marker (`full` False), the bit cells (1/8 of the side) next to the border that the photo shows
    black, the window then 1.9 cells deep; for a whole chessboard square (`full` True), the whole side, 0.3 of
    the side deep (None: decided from the photo). `white`: free white beyond the edge, a fraction of the side.
    Sub-pixel phases come from pooling many edges (`_pool`), not from each edge's slant."""
    out = []
    centre = quad.mean(0)
    Hh, Ww = img.shape[:2]
    for k in range(4):
        p0, p1 = quad[k], quad[(k + 1) % 4]
        e = p1 - p0
        L = float(np.linalg.norm(e))
        if L < 16:
            continue
        e /= L
        n = np.array([e[1], -e[0]])
        if np.dot(n, (p0 + p1) / 2 - centre) < 0:
            n = -n
        cell = L / 8.0
        hw, hb_sq = white * L, 0.3 * L
        reach = max(hw, hb_sq) + 2
        box = np.array([p0 + n * reach, p0 - n * reach, p1 + n * reach, p1 - n * reach])
        x0, y0 = np.maximum(np.floor(box.min(0)).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(box.max(0)).astype(int) + 1, [Ww, Hh])
        if x1 - x0 < 4 or y1 - y0 < 4:
            continue
        crop = img[y0:y1, x0:x1]
        lin = srgb_to_linear(crop) @ _LUMA
        gx = cv2.Sobel(lin, cv2.CV_64F, 1, 0, ksize=3) / 8
        gy = cv2.Sobel(lin, cv2.CV_64F, 0, 1, ksize=3) / 8
        yy, xx = np.mgrid[y0:y1, x0:x1]
        rel = np.stack([xx - p0[0], yy - p0[1]], -1).astype(np.float64)
        t, d = rel @ e, rel @ n
        g = gx * n[0] + gy * n[1]
        inside = (t >= 1.25 * cell) & (t <= L - 1.25 * cell)
        if not inside.any():
            continue
        lo, hi = np.percentile(lin[inside & (np.abs(d) < reach)], [5, 95])
        if hi - lo < 0.05:
            continue
        dark = lo + 0.25 * (hi - lo)
        probe_sq = inside & (d <= -1.1 * cell) & (d >= -hb_sq)
        full_q = bool(probe_sq.any() and np.percentile(lin[probe_sq], 98) < dark) if full is None else bool(full)
        bright = lo + 0.75 * (hi - lo)
        hb = hb_sq if full_q else 1.9 * cell
        probe = (-hb, -1.25 * cell) if full_q else (-1.75 * cell, -1.25 * cell)
        # cells 1..6 along the side, each with a 0.3-cell margin, kept where the photo shows deep black behind
        # the edge (a black bit, or the square) and clear white before it; the white window is the widest of
        # three that keeps the most cells (the free white beyond an edge is only known roughly)
        best = None
        for h_w in (hw, 0.75 * hw, 0.55 * hw):
            keep, cells = np.zeros_like(inside), 0
            for j in range(1, 7):
                s = (t >= (j + 0.3) * cell) & (t <= (j + 0.7) * cell)
                pb = s & (d >= probe[0]) & (d <= probe[1])
                pw = s & (d >= 0.5 * h_w) & (d <= h_w)
                if (pb.sum() >= 2 and pw.sum() >= 2 and np.percentile(lin[pb], 90) < dark
                        and np.percentile(lin[pw], 10) > bright):
                    keep |= s
                    cells += 1
            if best is None or cells > best[0]:
                best = (cells, keep, h_w)
        _, keep, hw = best
        half = min(hb, hw)
        c0 = c1 = 0.0
        for _ in range(2):
            dd = d - (c0 + c1 * t)
            a0, a1 = _grad_centroid(dd, t, np.where(keep, g, 0.0), half, L)
            c0, c1 = c0 + a0, c1 + a1
        d = d - (c0 + c1 * t)
        sel = keep & (np.abs(d) <= half)
        if sel.sum() < 40:
            continue
        out.append({"d": d[sel], "lin": lin[sel], "codes": crop[sel].astype(np.float64), "half": half,
                    "normal": n, "mid": (p0 + p1) / 2, "vertical": bool(abs(e[1]) > abs(e[0]))})
    return out


def esf_mtf(d: np.ndarray, v: np.ndarray, half: float, bin_w: float = _BIN,
            fmax: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """MTF from edge samples: distances `d` (N,) to the edge (any unit; white side positive) and values `v`
    (N,) linear, within +-`half`. The steps of `chart_measure.edge_mtf` (ESF binned at `bin_w`, empty bins
    interpolated, derivative, FFT zero-padded 4x, normalised at DC, divided by the finite difference's sinc)
    with a Tukey window (flat over the middle 60 %) in place of the Hamming window. Returns (frequencies in
    cycles per unit up to `fmax`, mtf), both (M,). ValueError when under 70 % of the bins hold a sample."""
    nb = int(2 * half / bin_w)
    idx = np.floor((d + half) / bin_w).astype(int)
    ok = (idx >= 0) & (idx < nb)
    cnt = np.bincount(idx[ok], minlength=nb)
    s = np.bincount(idx[ok], weights=v[ok], minlength=nb)
    have = cnt > 0
    if have.sum() < 0.7 * nb:
        raise ValueError("too few ESF bins filled")
    centres = np.arange(nb)
    esf = np.interp(centres, centres[have], s[have] / cnt[have])
    lsf = np.diff(esf)
    n = len(lsf)
    x = np.abs(np.arange(n) - (n - 1) / 2) / ((n - 1) / 2)
    lsf = lsf * np.where(x < 0.6, 1.0, 0.5 * (1 + np.cos(np.pi * (x - 0.6) / 0.4)))
    spec = np.abs(np.fft.rfft(lsf, n=4 * n))
    freq = np.fft.rfftfreq(4 * n, d=bin_w)
    mtf = spec / max(spec[0], 1e-12)
    mtf /= np.maximum(np.sinc(freq * bin_w), 0.2)
    keep = freq <= fmax
    return freq[keep], mtf[keep]


MIN_EDGES = 6
"""fewer usable edges than this give no MTF (a handful of short edges at VGA is not a measurement)"""


def _pool(edges: list[dict], scale: list[float] | None = None) -> tuple[float | None, float | None]:
    """(MTF50, overshoot) of the ESF pooled over `edges` (each normalised by its plateaus); distances divided
    by `scale` per edge (photo px per unit) when given. Overshoot: how far the pooled ESF (1 px bins) rises
    above its white plateau, a fraction of the edge's step (a camera's sharpening)."""
    if len(edges) < MIN_EDGES:
        return None, None
    ds, vs, halves = [], [], []
    for i, e in enumerate(edges):
        k = 1.0 if scale is None else scale[i]
        d, v, h = e["d"] / k, e["lin"], e["half"] / k
        lo = v[d < -0.6 * h].mean() if (d < -0.6 * h).any() else None
        hi = v[d > 0.6 * h].mean() if (d > 0.6 * h).any() else None
        if lo is None or hi is None or hi - lo < 0.02:
            continue
        ds.append(d)
        vs.append((v - lo) / (hi - lo))
        halves.append(h)
    if len(ds) < MIN_EDGES:
        return None, None
    half = float(np.min(halves))
    d, v = np.concatenate(ds), np.concatenate(vs)
    k = 1.0 if scale is None else float(np.median(scale))     # bins of 1/4 photo px, in the unit's terms
    try:
        f, m = esf_mtf(d, v, half, _BIN / k, fmax=min(2.0, 0.5 * k / _BIN))
    except ValueError:
        return None, None
    idx = np.floor(d[np.abs(d) < half] * k).astype(int)
    vv = v[np.abs(d) < half]
    prof = np.bincount(idx - idx.min(), vv) / np.maximum(np.bincount(idx - idx.min()), 1)
    return mtf50(f, m), float(prof.max() - 1.0)


def _tone_noise(edges: list[dict]) -> dict:
    """Plateau levels (grey codes), linear contrast and the noise about the ESF on each plateau (codes,
    per channel, mean), over all edges."""
    blacks, whites, lb, lw, rb, rw = [], [], [], [], [], []
    for e in edges:
        d, h, c = e["d"], e["half"], e["codes"]
        nb = max(int(2 * h), 2)
        idx = np.clip(((d + h) / (2 * h) * nb).astype(int), 0, nb - 1)
        cnt = np.maximum(np.bincount(idx, minlength=nb), 1)
        fit = np.stack([np.bincount(idx, c[:, j], nb) / cnt for j in range(3)], 1)[idx]   # ESF per channel, 1 px bins
        res = c - fit
        pb, pw = d < -0.5 * h, d > 0.5 * h
        if pb.sum() < 10 or pw.sum() < 10:
            continue
        blacks.append(c[pb].mean())
        whites.append(c[pw].mean())
        lb.append(e["lin"][pb].mean())
        lw.append(e["lin"][pw].mean())
        rb.append(res[pb])
        rw.append(res[pw])
    if not blacks:
        return {}
    def robust_std(r):   # per channel, 1.4826 MAD (a stray dark or white pixel does not count), mean
        return float(np.mean(1.4826 * np.median(np.abs(r - np.median(r, 0)), 0)))
    nb_, nw_ = robust_std(np.concatenate(rb)), robust_std(np.concatenate(rw))
    black, white = float(np.median(blacks)), float(np.median(whites))
    return {"black": black, "white": white, "contrast": float(np.median(lb) / max(np.median(lw), 1e-9)),
            "noise_black": nb_, "noise_white": nw_, "snr": (white - black) / max(nw_, 1e-9)}


def _local_scale(H: np.ndarray, pt: np.ndarray, normal: np.ndarray) -> float:
    """Photo px per board unit along the photo direction `normal` at photo point `pt`, through H (board -> photo)."""
    Hi = np.linalg.inv(H)
    a = cv2.perspectiveTransform(np.array([[pt, pt + normal]], np.float64), Hi)[0]
    return 1.0 / max(float(np.linalg.norm(a[1] - a[0])), 1e-12)


def measure_photo(img: np.ndarray, specs: list[BoardSpec] | None = None) -> dict:
    """All measures of one BGR photo (uint8 (H, W, 3)) of a printed board. `specs`: the boards to try
    (default: all of `KNOWN_BOARDS`). UserError when no board is found or no edge can be measured."""
    if img is None or img.ndim != 3 or img.dtype != np.uint8:
        raise UserError("expected an 8-bit colour photo")
    specs = [s for v in KNOWN_BOARDS.values() for s in v] if specs is None else specs
    quads, decoded = find_quads(img)
    reg = register_board(quads, specs)
    out = {"quads": int(len(quads)), "mode": "quads"}
    full, white = [None] * len(quads), [0.15] * len(quads)
    if reg is None and decoded.any():      # no board: the decoded markers only (stray quads are not markers)
        quads = quads[decoded]
        full, white = [None] * len(quads), [0.15] * len(quads)
        out["quads"] = int(len(quads))
    if reg is not None:
        spec = reg["spec"]
        _, tfull = board_quads(spec)
        full = [None] * len(quads)
        r = spec.ratio
        for p, t, _ in reg["matched"]:
            full[p] = bool(tfull[t])
            white[p] = (min(0.2, 0.8 * r) if spec.kind == "grid" else
                        0.8 * (1 - r) / 2 if tfull[t] else min(0.3, 0.8 * (1 - r) / (2 * r)))
        out.update(mode="board", board=f"{spec.kind} {spec.cols}x{spec.rows} ratio {spec.ratio}",
                   matched=len(reg["matched"]), reproj_rms_px=round(reg["rms_px"], 3))
    edges = []
    for q, fq, wq in zip(quads, full, white):
        edges += edge_samples(img, q, fq, wq)
    if not edges:
        raise UserError("no board edge could be measured in the photo (too small, too blurred, or too square on)")
    out["edges"] = len(edges)
    out["mtf50_px"], out["overshoot"] = _pool(edges)
    out["mtf50_px_x"] = _pool([e for e in edges if e["vertical"]])[0]
    out["mtf50_px_y"] = _pool([e for e in edges if not e["vertical"]])[0]
    out["mtf50_snap"] = None
    if reg is not None:
        k = snap_per_unit(reg["spec"])
        scale = [_local_scale(reg["H"], e["mid"], e["normal"]) / k for e in edges]   # photo px per snapshot px
        out["mtf50_snap"] = _pool(edges, scale)[0]
        out["photo_px_per_snap_px"] = float(np.median(scale))
    out.update(_tone_noise(edges))
    return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in out.items()}
