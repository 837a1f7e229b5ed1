"""`snapshot3d bench calibrate` (issue 38's targets): photograph the calibration chart through each physical
preset with several seeds and check what `calibrate` measures against the simulator's own values.

- MTF50 against the simulator's own: the same seed photographed without sensor noise and at JPEG quality 100
  (the same print, pose, light and blur: every other draw identical) and measured the same way; what is left
  between the two is what noise, JPEG and the print's texture do to the measure. Beside it, the first
  reference (`mtf50_otf`): the blur-free twin's edges times the blur kernel's own transfer function along
  each edge's normal in snapshot pixels (through the photo's homography). It reads 10-17 % above the
  noise-free photo itself at moderate and severe, so it is not the simulator's value: the scan resamples
  the photo (bilinear, 1.8 photo pixels a step) after the blur, and a sharp twin's edges keep content there
  that a blurred photo's do not (docs/calibration.md).
- gain and noise (`--pilots`): the simulator's own channel as the print codec sees it at the chart's
  operating point (`codec_reference`): the print codec's carriers (random 16x4 planes) on a flat mid grey at
  the chart's carrier amplitude, photographed with the same seed. Each band's gain and noise (relative to the
  print noise model) from `print_read.band_response`, the overall gain and unit noise from the pilots
  (`print_channel.measure`), against the chart's `bands` and `print_channel`. (The reference before was a
  print snapshot in a textured host: there `band_response`'s Y2 gains measure mostly the host's own texture,
  and what the payload keeps depends on the host's brightness: docs/calibration.md.)
- nearest preset: right or wrong per photo; the calibrate time per photo (scan + measure).
`--reference` prints the `scanner.calibrate.PRESET_REFERENCE` table from seeds 100-111 instead."""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from snapshot3d.errors import UserError

from .common import PHYSICAL, write_report

__all__ = ["chart_capture", "predicted_mtf50", "reference_mtf50", "twin_mtf50", "codec_reference",
           "bench_calibrate_command"]


def chart_capture(preset, seed: int, sheet=None):
    """(photo BGR, truth) of the chart's sheet (2 dots per snapshot pixel) through `preset` with `seed`."""
    from snapshot3d.scanner.sheet import chart_sheet
    from snapshot3d.scanner.simulate import simulate

    data, _, truth = simulate(chart_sheet(2, caption=False) if sheet is None else sheet, preset, seed)
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR), truth


def _otf(truth: dict, vertical: bool, freq: np.ndarray, at=(130.0, 68.0)) -> np.ndarray:
    """|OTF| of the simulated blur along snapshot x (vertical edges) or y, at snapshot point `at`."""
    from snapshot3d.scanner import layout
    from snapshot3d.scanner.simulate import blur_kernel

    s = truth["sampled"]
    psf = blur_kernel(s["defocus_px"], s["motion_px"], np.deg2rad(s["motion_angle_deg"]))
    H = cv2.getPerspectiveTransform(layout.snapshot_corners().astype(np.float32),
                                    np.array(truth["corners"], np.float32)).astype(np.float64)
    x, y = at
    p = H @ [x, y, 1.0]
    J = np.array([[H[0, 0] * p[2] - p[0] * H[2, 0], H[0, 1] * p[2] - p[0] * H[2, 1]],
                  [H[1, 0] * p[2] - p[1] * H[2, 0], H[1, 1] * p[2] - p[1] * H[2, 1]]]) / p[2] ** 2
    r = psf.shape[0] // 2
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    snap = np.linalg.solve(J, np.stack([xx.ravel(), yy.ravel()]).astype(np.float64))
    u = snap[0] if vertical else snap[1]
    return np.abs(np.exp(-2j * np.pi * np.outer(freq, u)) @ psf.ravel())


def predicted_mtf50(linear_noblur: np.ndarray, truth: dict) -> float:
    """The blur-free twin's prediction of a photo's MTF50: each edge's MTF measured on the twin's linear light
    (`calibrate.photo_linear`, (380, 380, 3) float RGB) times the blur's |OTF|; MTF50 of their mean, as
    `chart_measure.measure_mtf` takes it."""
    from snapshot3d.scanner import chart
    from snapshot3d.scanner.chart_measure import edge_mtf, mtf50

    lum = np.asarray(linear_noblur, np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    curves = []
    for x0, y0, x1, y1, vertical in chart.EDGE_ROIS:
        f, m = edge_mtf(lum[y0:y1, x0:x1], vertical)
        curves.append(m * _otf(truth, vertical, f, ((x0 + x1) / 2, (y0 + y1) / 2)))
    return mtf50(f, np.mean(curves, 0))


def reference_mtf50(preset, seed: int) -> float:
    """The simulator's own MTF50 for a photo: calibrate's MTF50 on the same seed photographed without sensor
    noise and at JPEG quality 100 (every other draw, the blur included, identical)."""
    from snapshot3d.scanner.calibrate import calibrate_image
    from snapshot3d.scanner.presets import get_preset

    clean = replace(get_preset(preset), noise_shot=(0.0, 0.0), noise_read=(0.0, 0.0), jpeg_quality=(100, 100))
    return float(calibrate_image(chart_capture(clean, seed)[0])["mtf50"])


def twin_mtf50(preset, seed: int, truth: dict) -> float:
    """`predicted_mtf50` of the blur-free twin of `preset`/`seed` (the first reference, kept beside)."""
    from snapshot3d.scanner.calibrate import photo_linear
    from snapshot3d.scanner.presets import get_preset
    from snapshot3d.scanner.scan import scan_image

    twin, _ = chart_capture(replace(get_preset(preset), defocus_px=(0.0, 0.0), motion_px=(0.0, 0.0)), seed)
    return predicted_mtf50(photo_linear(twin, scan_image(twin, chart=True).fit), truth)


def _chart_places(lay, boxes=None) -> np.ndarray:
    """(N, K) bool: the layout's chips whose coefficient lies inside `boxes` (snapshot pixel boxes (x0, y0, x1,
    y1); default the chart's two carrier squares)."""
    from snapshot3d.codecs import bands
    from snapshot3d.scanner import chart

    masks = []
    for b in lay.bands:
        f = 2 ** int(b[-3])
        m = np.zeros(bands.band_shape(b, chart.N), bool)
        for x0, y0, x1, y1 in chart.CARRIER_BOXES if boxes is None else boxes:
            m[(y0 + f - 1) // f:y1 // f, (x0 + f - 1) // f:x1 // f] = True
        masks.append(m.ravel())
    return np.concatenate(masks)[lay.chips]


def _square_weights(cap: np.ndarray, names) -> np.ndarray:
    """(squares, bands): how much the print codec's matched filters weigh each carrier square in each band of
    `names`: the sum of 1/n^2 over the band's coefficients there (a chip's filter times carrier, q w, goes as
    1/n^2 for n the print noise model `band_noise` of the capture (380, 380, 3) uint8 RGB)."""
    from snapshot3d.codecs.print_carriers import band_noise
    from snapshot3d.scanner import chart

    model = band_noise(cap / 255.0)
    out = np.zeros((len(chart.CARRIER_BOXES), len(names)))
    for j, b in enumerate(names):
        f = 2 ** int(b[-3])
        for i, (x0, y0, x1, y1) in enumerate(chart.CARRIER_BOXES):
            out[i, j] = float(np.sum(model[b][y0 // f:y1 // f, x0 // f:x1 // f] ** -2.0))
    return out


def _carrier_response(cap: np.ndarray, snap: np.ndarray, lay, keep: np.ndarray) -> dict:
    """What a capture kept of the print codec's carriers (`print_read.band_response`'s measure, on the chips
    `keep` (N, K) bool): per band, the least-squares gain of every carrier's matched-filter reading against
    the digital snapshot's, and the noise power left relative to the print noise model; over all bands the
    same with the pilots' gain estimator."""
    from snapshot3d.codecs import bands
    from snapshot3d.codecs.print_carriers import filters, flat, noise_map
    from snapshot3d.scanner import chart

    c = cap / 255.0
    _, q = filters(lay, c)
    q = q * keep
    edges = np.cumsum([int(np.prod(bands.band_shape(b, chart.N))) for b in lay.bands])
    band = np.searchsorted(edges, lay.chips, side="right")
    nb = len(lay.bands)

    def per_band(x):   # (N, K) -> (N, nb) sums over each band's chips
        idx = (np.arange(len(x))[:, None] * nb + band).ravel()
        return np.bincount(idx, weights=x.ravel(), minlength=len(x) * nb).reshape(len(x), nb)

    read = per_band(flat(bands.analyse(c), lay.bands)[lay.chips] * q)
    sent = per_band(flat(bands.analyse(snap / 255.0), lay.bands)[lay.chips] * q)
    var = per_band(q * q * noise_map(c, lay.bands)[lay.chips])
    gain = np.einsum("nb,nb->b", read, sent) / np.maximum(np.einsum("nb,nb->b", sent, sent), 1e-30)
    unit = np.sum((read - gain * sent) ** 2, 0) / np.maximum(var.sum(0), 1e-30)
    r, t = read.sum(1), sent.sum(1)
    # over all bands the pilots' estimator (`print_read.restore`: the mean of reading x sign over the mean
    # expected reading); a least-squares fit over the carriers reads within 0.3 % of it here
    g_all = float(np.sum(r * np.sign(t)) / max(float(np.sum(np.abs(t))), 1e-30))
    return {"gain": g_all, "unit": float(np.sum((r - g_all * t) ** 2) / max(var.sum(), 1e-30)),
            "band_gain": dict(zip(lay.bands, gain.tolist())), "band_unit": dict(zip(lay.bands, unit.tolist()))}


def _mean(parts: list[dict]) -> dict:
    """The mean of `_carrier_response` results (numbers and band -> number dicts) over draws."""
    return {k: ({b: float(np.mean([p[k][b] for p in parts])) for b in v} if isinstance(v, dict)
                else float(np.mean([p[k] for p in parts]))) for k, v in parts[0].items()}


def codec_reference(preset, seed: int, rng, draws: int = 3) -> dict:
    """The simulator's own channel through `preset`/`seed` as the print codec sees it at the chart's operating
    point: random 16x4 planes embedded in a flat mid grey (no host texture) at the chart's carrier amplitude
    (`chart.CARRIER_STD`), photographed with the same seed (the same print, pose, light and camera draws), for
    `draws` draws of the planes (one draw's band gains spread by 1-6 % at `severe`, most in the chroma bands).
    Returns, each the mean over the draws:
    - "expected": per band the gain the codec's carriers read at the chart's places, each carrier square's own
      gain (`squares`, the carriers' chips inside it) weighed as the codec's filters weigh the square
      (`_square_weights`), and over all bands (`gain`) the same with each band weighed by its energy too.
      This is the target's reference: at `severe` the two squares' gains differ by up to 5x, and one
      least-squares fit over the carriers weighs the squares by which carriers drew large values.
      `band_gain_stderr`: its relative standard error over the draws;
    - "places": the carriers' response (`_carrier_response`: gain and unit noise over all bands and per band)
      over both squares' chips; "square": the same over the whole snapshot square;
    - "pilots": the pilots' `print_channel.measure` (gain, unit)."""
    from snapshot3d.codecs.print_carriers import PRINT_BANDS, print_layout
    from snapshot3d.codecs.print_channel import measure
    from snapshot3d.codecs.print_embed import embed
    from snapshot3d.scanner import chart
    from snapshot3d.scanner.qr import SheetMeta
    from snapshot3d.scanner.roundtrip import capture

    lay = print_layout(16, 4)
    keeps = [_chart_places(lay, (box,)) for box in chart.CARRIER_BOXES]
    places, square, pilots, per_sq, weights = [], [], [], [], []
    for _ in range(draws):
        planes = np.clip(rng.normal(0, 0.4, (3, 4, 16, 16)), -1, 1)
        snap = embed(np.full((380, 380, 3), 0.5), planes, host_psnr=-20 * np.log10(chart.CARRIER_STD))
        cap = capture(snap, SheetMeta(codec="print-2", planes=(16, 4)), preset, seed)
        places.append(_carrier_response(cap, snap, lay, _chart_places(lay)))
        square.append(_carrier_response(cap, snap, lay, np.ones(lay.chips.shape, bool)))
        ch = measure(snap, cap, 16, 4)
        pilots.append({"gain": ch.gain, "unit": ch.unit})
        per_sq.append([list(_carrier_response(cap, snap, lay, k)["band_gain"].values()) for k in keeps])
        weights.append(_square_weights(cap, list(lay.bands)))
    g, w = np.mean(per_sq, 0), np.mean(weights, 0)   # (squares, bands)
    ew = w * np.array([PRINT_BANDS[b] for b in lay.bands])   # over all bands as carriers: each band by its energy
    each = np.sum(np.array(per_sq) * np.array(weights), 1) / np.sum(weights, 1)   # (draws, bands): each draw's reading
    err = np.std(each, 0, ddof=1) / np.sqrt(draws) / np.mean(each, 0) if draws > 1 else np.full(len(lay.bands), np.nan)
    expected = {"gain": float(np.sum(g * ew) / np.sum(ew)),
                "band_gain": dict(zip(lay.bands, (np.sum(g * w, 0) / np.sum(w, 0)).tolist())),
                "band_gain_stderr": dict(zip(lay.bands, err.tolist())),
                "squares": {b: g[:, j].tolist() for j, b in enumerate(lay.bands)}}
    return {"expected": expected, "places": _mean(places), "square": _mean(square), "pilots": _mean(pilots)}


def bench_calibrate_command(args) -> int:
    from snapshot3d.scanner.calibrate import calibrate_image

    t_start = time.perf_counter()
    for opt in ("seeds", "draws"):
        if getattr(args, opt, 1) < 1:
            raise UserError(f"--{opt} must be at least 1, not {getattr(args, opt)}")
    if args.reference:
        seeds = range(100, 112)
        print("PRESET_REFERENCE = {")
        for name in PHYSICAL:
            feats = []
            for seed in seeds:
                prof = calibrate_image(chart_capture(name, seed)[0])
                feats.append(np.log([prof["mtf50"], prof["channel"]["gain"], prof["channel"]["unit"]]))
            mu, sd = np.mean(feats, 0), np.std(feats, 0, ddof=1)
            print(f'    "{name}": ' + str(tuple((round(float(m), 3), round(float(s), 3)) for m, s in zip(mu, sd))) + ",")
        print("}")
        return 0
    rows, rng = [], np.random.default_rng(0)
    for name in PHYSICAL:
        for seed in range(args.seeds):
            img, truth = chart_capture(name, seed)
            t0 = time.perf_counter()
            prof = calibrate_image(img)
            ms = (time.perf_counter() - t0) * 1e3
            ref = reference_mtf50(name, seed)
            otf = twin_mtf50(name, seed, truth)
            row = {"preset": name, "seed": seed, "nearest": prof["nearest_preset"],
                   "right": int(prof["nearest_preset"] == name), "mtf50": prof["mtf50"], "mtf50_sim": round(ref, 4),
                   "mtf50_err": round(prof["mtf50"] / ref - 1, 4), "mtf50_otf": round(otf, 4),
                   "mtf50_otf_err": round(prof["mtf50"] / otf - 1, 4), "gain": prof["channel"]["gain"],
                   "unit": prof["channel"]["unit"], "noise_std": prof["noise_std"],
                   "misregistration_px": prof["misregistration_px"], "calibrate_ms": round(ms, 1)}
            if args.pilots:
                ref = codec_reference(name, seed, rng, args.draws)
                pc = prof["print_channel"]
                # band gains against the expected reading at the chart's places ("": the target), and against one
                # least-squares fit over the carriers at the places (pl_, the reference before) and over the square
                exp = {**ref["places"], **ref["expected"]}
                for tag, r in (("", exp), ("pl_", ref["places"]), ("sq_", ref["square"])):
                    errs = {b: prof["bands"][b]["gain"] / max(g, 1e-9) - 1 for b, g in r["band_gain"].items()}
                    uerr = {b: prof["bands"][b]["unit"] / max(u, 1e-12) - 1 for b, u in r["band_unit"].items()}
                    row.update({f"{tag}bands_within_10pct": sum(abs(e) <= 0.10 for e in errs.values()),
                                f"{tag}band_units_within_25pct": sum(abs(e) <= 0.25 for e in uerr.values()),
                                f"{tag}gain_err": round(pc["gain"] / r["gain"] - 1, 4),
                                f"{tag}unit_err": round(pc["unit"] / r["unit"] - 1, 4),
                                **{f"{tag}gain_err_{b}": round(e, 4) for b, e in errs.items()},
                                **{f"{tag}unit_err_{b}": round(e, 4) for b, e in uerr.items()}})
                sq_err = [prof["bands"][b]["squares"][i] / max(g, 1e-9) - 1
                          for b, gs in ref["expected"]["squares"].items() for i, g in enumerate(gs)]
                row.update(ref_stderr_max=round(max(ref["expected"]["band_gain_stderr"].values()), 4))
                row.update(squares_within_10pct=sum(abs(e) <= 0.10 for e in sq_err), squares_n=len(sq_err),
                           squares_err_median_abs=round(float(np.median(np.abs(sq_err))), 4))
                row.update(print_gain=pc["gain"], print_unit=pc["unit"], ref_gain=round(ref["expected"]["gain"], 4),
                           ref_unit=float(f'{ref["places"]["unit"]:.4g}'), pilot_gain=round(ref["pilots"]["gain"], 4),
                           pilot_unit=float(f'{ref["pilots"]["unit"]:.4g}'),
                           pilot_gain_err=round(pc["gain"] / ref["pilots"]["gain"] - 1, 4),
                           pilot_unit_err=round(pc["unit"] / ref["pilots"]["unit"] - 1, 4))
            rows.append(row)
            print({k: row[k] for k in row if k in ("preset", "seed", "nearest", "mtf50", "mtf50_sim", "mtf50_otf", "gain",
                                                    "ref_gain", "bands_within_10pct", "band_units_within_25pct",
                                                    "unit_err", "sq_bands_within_10pct", "calibrate_ms")}, flush=True)
    summary = {}
    for name in PHYSICAL:
        r = [x for x in rows if x["preset"] == name]
        s = {"photos": len(r), "nearest_right": sum(x["right"] for x in r) / len(r),
             "mtf50_abs_err_max": max(abs(x["mtf50_err"]) for x in r),
             "mtf50_within_15pct": sum(abs(x["mtf50_err"]) <= 0.15 for x in r) / len(r),
             "mtf50_otf_abs_err_max": max(abs(x["mtf50_otf_err"]) for x in r),
             "mtf50_otf_within_15pct": sum(abs(x["mtf50_otf_err"]) <= 0.15 for x in r) / len(r),
             "calibrate_ms_median": float(np.median([x["calibrate_ms"] for x in r]))}
        if args.pilots:
            def frac(key, lim, n=1):   # share of the values within lim (n values per photo: columns key_*)
                vals = [abs(x[k]) for x in r for k in x if (k.startswith(key + "_") if n > 1 else k == key)]
                return sum(v <= lim for v in vals) / len(vals)

            def med(key):
                return float(np.median([abs(x[k]) for x in r for k in x if k.startswith(key + "_")]))

            for tag in ("", "pl_", "sq_"):
                s.update({f"{tag}gain_within_10pct": frac(f"{tag}gain_err", 0.10),
                          f"{tag}unit_within_25pct": frac(f"{tag}unit_err", 0.25),
                          f"{tag}band_gains_within_10pct": frac(f"{tag}gain_err", 0.10, 7),
                          f"{tag}band_units_within_25pct": frac(f"{tag}unit_err", 0.25, 7),
                          f"{tag}band_gain_err_median_abs": med(f"{tag}gain_err"),
                          f"{tag}band_unit_err_median_abs": med(f"{tag}unit_err")})
            s.update(square_band_gains_within_10pct=sum(x["squares_within_10pct"] for x in r)
                                                            / sum(x["squares_n"] for x in r))
            s.update(pilot_gain_within_10pct=frac("pilot_gain_err", 0.10),
                     pilot_unit_within_25pct=frac("pilot_unit_err", 0.25),
                     pilot_gain_err_median=float(np.median([x["pilot_gain_err"] for x in r])),
                     pilot_unit_err_median=float(np.median([x["pilot_unit_err"] for x in r])))
        summary[name] = s
    doc = write_report(Path(args.out), "calibrate", rows,
                       {"targets": {"gain": "within 10%", "noise": "within 25%", "mtf50": "within 15%",
                                    "nearest_preset": ">= 90% right", "calibrate_s": "<= 2 s, 12 MP, 2 cores"},
                        "summary": summary, "seconds": round(time.perf_counter() - t_start, 1)})
    for name, s in doc["summary"].items():
        print(name, s)
    return 0
