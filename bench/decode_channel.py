"""`snapshot3d bench decode-channel` (issue 38 item 4): the channel report every print decode carries
(`viewer.channel`), on simulated photos of print sheets (scenes x hosts x physical presets x seeds).

Per photo: the report's gain, noise, SNR, per-band gains, nearest preset and advice; what the simulator
drew (defocus, motion, noise, JPEG quality) and the snapshot's size in the photo, to check the advice
against; the channel report's own time (measured again alone on the capture: median and best of 5);
and `restore_psnr` (decoded views against the reference renderer's, 20 views of 128) beside the quality
estimate's `restore_psnr_expected_db`.
The summary counts the nearest preset right per preset, the advice against the simulator's draw (steadier
where its defocus plus motion passed `viewer.channel.STEADY_PX`, else closer; also for the rule before the photo
check, the blur the pilots' gain points to) and the estimate's error. Rows carry the photo check's measures
(`check_blur` in snapshot pixels, `check_glare`, `check_tilt`).
`--reference` takes seeds 100-105 and prints `viewer.channel.CHANNEL_REFERENCE` (mean and spread of log gain
and log noise per preset), `BLUR_FIT` and what chose the features (`feature_choice`) instead of scoring; its
rows go to decode_channel_reference.{csv,json}."""
from __future__ import annotations

import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from .common import PHYSICAL, write_report

__all__ = ["bench_decode_channel_command", "REFERENCE_SEEDS"]

REFERENCE_SEEDS = range(100, 106)


def _alone_ms(snapshot: np.ndarray, meta, info: dict, px: float, repeats: int = 5) -> tuple[float, float]:
    """The channel report's time on one capture: (median, best) of `repeats` (the best is its own cost without
    other processes': the bench's machine may be shared)."""
    from snapshot3d.viewer.channel import channel_report

    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        channel_report(meta.codec, snapshot, meta.planes, info, px)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), min(times)


def _row(photo: Path, ref: np.ndarray, truth: dict, size: int) -> dict:
    from snapshot3d.metrics import psnr
    from snapshot3d.viewer.channel import px_per_pixel
    from snapshot3d.viewer.decode import decode_photo, read_input
    from snapshot3d.viewer.media import restore_planes

    dec = decode_photo(photo, size=size)
    ch, q = dec.report["channel"], dec.report["quality_estimate"]
    res, snap, meta, _ = read_input(photo)
    _, info = restore_planes(snap, meta)
    px = px_per_pixel(res.corners)
    s, check = truth["sampled"], dec.report["scan"]["photo"]
    return {"gain": ch["gain"], "noise": ch["noise"], "snr_db": ch["snr_db"],
            "log_gain": round(math.log(ch["gain"]), 4), "log_noise": round(math.log(ch["noise"]), 4),
            **{f"gain_{b}": v for b, v in ch["band_gain"].items()},
            "nearest": ch["nearest_preset"], "advice": ch["advice"], "px_per_pixel": round(px, 3),
            "defocus_px": round(s["defocus_px"], 3), "motion_px": round(s["motion_px"], 3),
            "blur_snapshot_px": round((s["defocus_px"] + s["motion_px"]) / px, 3),
            "check_blur": check["blur_px"], "check_glare": check["glare_share"], "check_tilt": check["tilt_deg"],
            "noise_shot": round(s["noise_shot"], 5), "noise_read": round(s["noise_read"], 5),
            "jpeg_quality": s["jpeg_quality"], "channel_ms_in_decode": ch["ms"],
            **dict(zip(("channel_ms", "channel_ms_best"), (round(t, 2) for t in _alone_ms(snap, meta, info, px)))),
            "restore_psnr": round(float(psnr(dec.views, ref)), 2),
            "restore_psnr_expected_db": q["restore_psnr_expected_db"]}


def _rows(scenes: list[str], hosts: list[str], seeds, size: int) -> list[dict]:
    from snapshot3d import formats
    from snapshot3d.errors import UserError
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.qr import scene_meta
    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.scanner.simulate import simulate
    from snapshot3d.scene import load_scene_file

    from .decode import _reference, _snapshot

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for spath in scenes:
            scene = load_scene_file(spath)
            ref = _reference(scene, size)
            for host in hosts:
                sheet = render_sheet(_snapshot(scene, formats.PRINT_CODEC, load_host("builtin:" + host)),
                                     scene_meta(scene, formats.PRINT_CODEC), 2)
                for preset in PHYSICAL:
                    for seed in seeds:
                        data, ext, truth = simulate(sheet, preset, seed)
                        photo = Path(tmp) / f"photo{ext}"
                        photo.write_bytes(data)
                        head = {"scene": Path(spath).stem, "host": host, "preset": preset, "seed": seed}
                        try:
                            row = {**head, **_row(photo, ref, truth, size)}
                        except UserError as e:   # a photo the scanner refuses is a row with its cause
                            row = {**head, "failed": str(e)[:80]}
                        rows.append(row)
                        print({k: row.get(k) for k in ("scene", "host", "preset", "seed", "gain", "noise", "snr_db",
                                                       "nearest", "channel_ms", "restore_psnr",
                                                       "restore_psnr_expected_db")}, flush=True)
    return rows


def reference_table(rows: list[dict]) -> tuple[dict, tuple]:
    """{preset: ((mean, std) of log gain, log noise)} over `rows` (sample std), and the least-squares line
    log(blur in snapshot pixels + 0.05) = a + b log(gain) (`viewer.channel.BLUR_FIT`) with its RMS error and
    correlation."""
    ok = [r for r in rows if "failed" not in r]
    table = {}
    for name in PHYSICAL:
        x = np.array([[r["log_gain"], r["log_noise"]] for r in ok if r["preset"] == name])
        mu, sd = x.mean(0), x.std(0, ddof=1)
        table[name] = tuple((round(float(m), 3), round(float(s), 3)) for m, s in zip(mu, sd))
    g = np.array([r["log_gain"] for r in ok])
    y = np.log(np.array([r["blur_snapshot_px"] for r in ok]) + 0.05)
    (a, b), *_ = np.linalg.lstsq(np.stack([np.ones_like(g), g], 1), y, rcond=None)
    pred = a + b * g
    fit = (round(float(a), 3), round(float(b), 3), round(float(np.sqrt(np.mean((pred - y) ** 2))), 3),
           round(float(np.corrcoef(pred, y)[0, 1]), 3))
    return table, fit


def feature_choice(rows: list[dict]) -> dict:
    """What chose `viewer.channel.FEATURES` and the advice: per candidate feature set (logs of the pilots' gain,
    noise, and the finest bands' gain over the next level's), how often the nearest preset (diagonal Gaussian
    fitted to the other photos) is right, left one out; and within each preset (values less the preset's mean)
    the correlation of the pilots' log noise with the simulator's log read noise, log shot noise and log blur
    in snapshot pixels."""
    ok = [r for r in rows if "failed" not in r]
    pre = np.array([r["preset"] for r in ok])
    v = {"gain": np.array([r["log_gain"] for r in ok]), "noise": np.array([r["log_noise"] for r in ok]),
         "fine": np.log(np.array([(r["gain_Y1LH"] + r["gain_Y1HL"]) / (r["gain_Y2LH"] + r["gain_Y2HL"]) for r in ok])),
         "read": np.log([r["noise_read"] for r in ok]), "shot": np.log([r["noise_shot"] for r in ok]),
         "blur": np.log(np.array([r["blur_snapshot_px"] for r in ok]) + 0.05)}

    def loo(keys):
        f, right = np.stack([v[k] for k in keys], 1), 0
        for i in range(len(f)):
            others = np.arange(len(f)) != i
            dist = {}
            for name in PHYSICAL:
                s = others & (pre == name)
                mu, sd = f[s].mean(0), f[s].std(0, ddof=1)
                dist[name] = 0.5 * np.sum(((f[i] - mu) / sd) ** 2) + np.sum(np.log(sd))
            right += min(dist, key=dist.get) == pre[i]
        return round(right / len(f), 3)

    within = {k: x - np.array([x[pre == p].mean() for p in pre]) for k, x in v.items()}
    return {"nearest_right_left_one_out": {"+".join(k): loo(k) for k in (("gain",), ("gain", "noise"),
                                                                           ("gain", "noise", "fine"))},
            "noise_within_preset_corr": {k: round(float(np.corrcoef(within["noise"], within[k])[0, 1]), 3)
                                         for k in ("read", "shot", "blur")}}


def _summary(rows: list[dict]) -> dict:
    from snapshot3d.viewer.channel import STEADY_PX, blur_px

    ok = [r for r in rows if "failed" not in r]
    out = {"photos": len(rows), "failed": len(rows) - len(ok),
           "channel_ms_median": float(np.median([r["channel_ms"] for r in ok])),
           "channel_ms_max": float(np.max([r["channel_ms"] for r in ok])),
           "channel_ms_best_median": float(np.median([r["channel_ms_best"] for r in ok])), "per_preset": {}}
    for name in PHYSICAL:
        r = [x for x in ok if x["preset"] == name]
        err = [x["restore_psnr_expected_db"] - x["restore_psnr"] for x in r
               if x["restore_psnr_expected_db"] is not None]
        out["per_preset"][name] = {
            "photos": len(r), "nearest_right": sum(x["nearest"] == name for x in r),
            "nearest": {k: sum(x["nearest"] == k for x in r) for k in ("better than mild", *PHYSICAL)},
            "advice": {a: sum(a in x["advice"] for x in r) for a in ("closer", "steadier", "nothing")},
            # the advice against what the simulator drew: steadier where its defocus plus motion passed STEADY_PX
            "advice_agrees": sum(("steadier" in x["advice"]) == (x["defocus_px"] + x["motion_px"] > STEADY_PX)
                                 for x in r if "nothing" not in x["advice"]),
            # the rule before the photo check's blur: the blur that the pilots' gain points to
            "advice_agrees_gain_rule": sum((blur_px(x["gain"], x["px_per_pixel"]) > STEADY_PX) ==
                                           (x["defocus_px"] + x["motion_px"] > STEADY_PX)
                                           for x in r if "nothing" not in x["advice"]),
            "estimate_minus_measured_db_median": round(float(np.median(err)), 2) if err else None,
            "estimate_minus_measured_db_max": round(float(np.max(err)), 2) if err else None}
    return out


def bench_decode_channel_command(args) -> int:
    t0 = time.perf_counter()
    scenes, hosts = args.scenes.split(","), args.hosts.split(",")
    if args.reference:
        rows = _rows(scenes, hosts, REFERENCE_SEEDS, args.size)
        table, fit = reference_table(rows)
        print("CHANNEL_REFERENCE = {")
        for name, ref in table.items():
            print(f'    "{name}": {ref},')
        print("}")
        print(f"BLUR_FIT = {fit[:2]}  # RMS error {fit[2]}, correlation {fit[3]}")
        choice = feature_choice(rows)
        print(choice)
        write_report(Path(args.out), "decode_channel_reference", rows,
                     {"seeds": list(REFERENCE_SEEDS), "reference": table, "blur_fit": fit, "choice": choice,
                      "summary": _summary(rows),
                      "seconds": round(time.perf_counter() - t0, 1)})
        return 0
    rows = _rows(scenes, hosts, range(args.seeds), args.size)
    doc = write_report(Path(args.out), "decode_channel", rows,
                       {"summary": _summary(rows), "seconds": round(time.perf_counter() - t0, 1)})
    print(doc["summary"])
    return 0
