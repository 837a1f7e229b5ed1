"""`snapshot3d bench channel --real` (issue 38 item 5): MTF, noise and tone of real camera photos of printed
ArUco / ChArUco boards (`../shared/data/photos/aruco/`, opencv_contrib's tutorial photos, 640 x 480), beside
the same measures (`board_measure.measure_photo`, one code path) on simulated photos of the same boards' exact
templates (`board_register.sheet_canvas` through `scanner.simulate`) at each physical preset. Writes
channel_real.{json,csv,png}."""
from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

from snapshot3d.errors import UserError

from .board_measure import measure_photo
from .board_register import BOARD_FILL, KNOWN_BOARDS, sheet_canvas

__all__ = ["MEASURES", "bench_channel_real_command"]

MEASURES = ["mtf50_px", "mtf50_snap", "overshoot", "noise_white", "noise_black", "black", "white", "contrast", "snr"]


def _real_photos(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))


def bench_channel_real_command(args) -> int:
    from snapshot3d.builtin import shared_data_dir
    from snapshot3d.scanner.simulate import simulate

    from .common import PHYSICAL, pyplot, write_report

    t0 = time.perf_counter()
    folder = Path(args.photos) if getattr(args, "photos", None) else None
    if folder is None:
        root = shared_data_dir()
        if root is None or not (root / "photos/aruco").is_dir():
            raise UserError("no real photos: ../shared/data/photos/aruco is absent; give --photos DIR")
        folder = root / "photos/aruco"
    if not folder.is_dir():
        raise UserError(f"--photos {folder}: not a folder")
    rows = []
    for p in _real_photos(folder):
        img = cv2.imread(str(p), cv2.IMREAD_COLOR)
        try:
            m = measure_photo(img)
        except UserError as e:
            print(f"{p.name}: {e}")
            continue
        rows.append({"source": "real", "photo": p.name, "preset": "", "seed": "", **m})
        print(p.name, {k: m.get(k) for k in ("mode", "board", "reproj_rms_px", *MEASURES)}, flush=True)
    if not rows:
        raise UserError(f"no board was measured in any photo of {folder}")
    sims = [KNOWN_BOARDS["charuco"][0], KNOWN_BOARDS["grid"][3]]    # ratio 0.5 ChArUco, 0.25 grid
    for spec in sims:
        canvas, _ = sheet_canvas(spec)
        for preset in PHYSICAL:
            for seed in range(args.seeds):
                data, _, _ = simulate(canvas, preset, seed)
                img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
                try:
                    m = measure_photo(img, [spec])
                except UserError as e:
                    print(f"{spec.kind} {preset} {seed}: {e}")
                    continue
                rows.append({"source": "simulated", "photo": f"{spec.kind} template", "preset": preset,
                             "seed": seed, **m})
                print(spec.kind, preset, seed, {k: m.get(k) for k in ("mode", "reproj_rms_px", *MEASURES)},
                      flush=True)
    summary = _summary(rows)
    out = Path(args.out)
    doc = write_report(out, "channel_real", rows, {
        "photos": str(folder), "seeds": args.seeds, "summary": summary,
        "assumption": "mtf50_snap: the board fills the frame the way it fills a sheet in the simulated sheets "
                      f"(board height with a half-square margin = {BOARD_FILL} of the sheet's height)",
        "seconds": round(time.perf_counter() - t0, 1)})
    _chart(rows, out / "channel_real.png", pyplot())
    for k, v in doc["summary"]["verdict"].items():
        print(f"{k}: {v}")
    return 0


def _summary(rows: list[dict]) -> dict:
    """Per measure: the real photos' values and median, each preset's (min, median, max), and where the real
    median lies among the presets' medians, mildest first, with a verdict: better than mild: the presets are
    pessimistic; like mild or moderate (within 10 %), or between them: about right; worse than moderate:
    optimistic."""
    from .common import PHYSICAL

    sign = {"mtf50_px": 1, "mtf50_snap": 1, "overshoot": 0, "noise_white": -1, "noise_black": -1, "black": -1,
            "white": 1, "contrast": -1, "snr": 1}          # +1: higher is better; 0: no better side
    real = [r for r in rows if r["source"] == "real"]
    out, verdict = {}, {}
    for k in MEASURES:
        rv = [r[k] for r in real if r.get(k) is not None]
        pre = {}
        for p in PHYSICAL:
            v = [r[k] for r in rows if r["source"] == "simulated" and r["preset"] == p and r.get(k) is not None]
            if v:
                pre[p] = {"min": float(np.min(v)), "median": float(np.median(v)), "max": float(np.max(v))}
        out[k] = {"real": {r["photo"]: r.get(k) for r in real}, "real_median": float(np.median(rv)) if rv else None,
                  "presets": pre}
        if not rv or len(pre) < len(PHYSICAL):
            verdict[k] = "not measured"
            continue
        med = float(np.median(rv))
        m = [pre[p]["median"] for p in PHYSICAL]
        if sign[k] == 0:
            verdict[k] = (f"real {med:.3g} above every preset's median ({max(m):.3g} at most)" if med > max(m) else
                          f"real {med:.3g} below every preset's median" if med < min(m) else
                          f"real {med:.3g} within the presets' medians")
            continue
        q = [sign[k] * x for x in m]      # quality, higher is better, mild first
        r = sign[k] * med
        near = int(np.argmin([abs(x - med) for x in m]))
        if abs(med - m[near]) <= 0.1 * abs(m[near]):          # within 10 % of one preset's median: like it
            where = f"like {PHYSICAL[near]}"
            word = "optimistic" if near == 2 else "about right"
        else:
            where = ("better than mild" if r > q[0] else "between mild and moderate" if r >= q[1] else
                     "between moderate and severe" if r >= q[2] else "worse than severe")
            word = ("pessimistic" if where == "better than mild" else "about right" if where.endswith("moderate")
                    else "optimistic")
        verdict[k] = f"real {med:.3g}: {where} (medians {', '.join(f'{x:.3g}' for x in m)}): presets {word}"
    return {"measures": out, "verdict": verdict}


def _chart(rows: list[dict], path: Path, plt) -> None:
    from .common import PHYSICAL

    fig, axes = plt.subplots(2, 5, figsize=(17, 6.5))
    real = [r for r in rows if r["source"] == "real"]
    colours = {"mild": "tab:green", "moderate": "tab:orange", "severe": "tab:red"}
    for ax, k in zip(axes.ravel(), MEASURES):
        for i, p in enumerate(PHYSICAL):
            v = [r[k] for r in rows if r["source"] == "simulated" and r["preset"] == p and r.get(k) is not None]
            if v:
                ax.plot([i, i], [min(v), max(v)], color=colours[p], lw=6, alpha=0.5, solid_capstyle="butt")
                ax.plot([i - 0.2, i + 0.2], [np.median(v)] * 2, color=colours[p], lw=2)
        for j, r in enumerate(real):
            if r.get(k) is not None:
                ax.plot(3.2 + 0.12 * j, r[k], "o", ms=5, color=f"C{j}")
        ax.set_xticks([0, 1, 2, 3.4], ["mild", "moderate", "severe", "real"], fontsize=8)
        ax.set_title(k, fontsize=9)
    key = axes.ravel()[-1]
    key.axis("off")
    for j, r in enumerate(real):
        key.plot([], [], "o", color=f"C{j}", label=f"{r['photo']} ({r.get('board') or 'quad by quad'})")
    key.legend(fontsize=7, loc="upper left", title="real photos (640 x 480)", title_fontsize=8)
    key.text(0, 0.05, "mtf50_snap: board assumed to fill the frame\nas it fills a sheet in the simulated ones",
             fontsize=7, transform=key.transAxes)
    fig.suptitle("Real photos of printed ArUco boards (dots) vs simulated photos of the same boards per preset "
                 "(bar: range, tick: median)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
