"""Charts of `bench scan` (matplotlib, imported only here): detection rate and corner error against tilt,
blur, noise and snapshot size, with the point where the scanner breaks marked; PSNR per severity."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from snapshot3d.errors import UserError

__all__ = ["break_points", "write_charts"]

_FACTORS = {"tilt": ("tilt_deg", "tilt (degrees)"), "blur": ("blur_px", "blur: defocus radius + motion/2 (px)"),
            "noise": ("noise_std", "sensor noise std at mid-grey (full scale 1)"),
            "size": ("coverage", "snapshot area / frame area")}
_DET_MIN, _ERR_MAX = 0.99, 0.5  # the scanner "breaks" where detection drops below or the median error exceeds


def _levels(rows, name):
    g = [r for r in rows if r["group"] == f"sweep-{name}"]
    out = []
    for lvl in sorted({r["level"] for r in g}):
        rs = [r for r in g if r["level"] == lvl]
        errs = [r["err_max"] for r in rs if r["detected"]]
        out.append((lvl, float(np.mean([r["detected"] for r in rs])),
                    float(np.median(errs)) if errs else np.nan, float(np.percentile(errs, 95)) if errs else np.nan,
                    float(np.median([r[_FACTORS[name][0]] for r in rs]))))
    return out


def break_points(rows: list[dict]) -> dict:
    """{factor: first swept level where detection < 99% or the median corner error > 0.5 px (or None)}."""
    out = {}
    for name in _FACTORS:
        lv = _levels(rows, name)
        order = lv[::-1] if name == "size" else lv  # small snapshots break, so walk sizes downwards
        hit = next((x for x in order if x[1] < _DET_MIN or (np.isfinite(x[2]) and x[2] > _ERR_MAX)), None)
        out[name] = None if hit is None else {"level": hit[0], "measured": hit[4], "detection_rate": hit[1],
                                              "median_err_px": hit[2]}
    return out


def write_charts(rows: list[dict], out: Path) -> None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise UserError("bench charts need matplotlib: pip install 'snapshot3d[train]'") from None
    bp = break_points(rows)
    fig, ax = plt.subplots(2, 4, figsize=(18, 8))
    for j, name in enumerate(_FACTORS):
        lv = _levels(rows, name)
        if not lv:
            continue
        x = [v[4] for v in lv]  # the measured value (median over the level's photos), e.g. the coverage reached
        ax[0, j].plot(x, [100 * v[1] for v in lv], "o-")
        ax[0, j].set_ylim(-5, 105)
        ax[0, j].set_ylabel("detection rate (%)")
        ax[1, j].plot(x, [v[2] for v in lv], "o-", label="median")
        ax[1, j].plot(x, [v[3] for v in lv], "s--", label="95th percentile")
        ax[1, j].axhline(_ERR_MAX, color="grey", lw=0.8)
        ax[1, j].set_yscale("log")
        ax[1, j].set_ylabel("worst-corner error (snapshot px)")
        ax[1, j].legend(fontsize=8)
        for i in range(2):
            ax[i, j].set_xlabel(_FACTORS[name][1] + " (swept; rest as mild)")
            if name == "size":
                ax[i, j].set_xscale("log")
            if bp.get(name):
                ax[i, j].axvline(bp[name]["measured"], color="red", ls=":", lw=2)
                ax[i, j].text(bp[name]["measured"], ax[i, j].get_ylim()[1], " breaks", color="red", va="top",
                              fontsize=9)
    fig.suptitle("scanner vs one factor at a time (red: first level with detection < 99% or median error > 0.5 px)")
    fig.tight_layout()
    fig.savefig(out / "scan_breaks.png", dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(1, 4, figsize=(18, 4.5))
    colours = {"mild": "tab:green", "moderate": "tab:orange", "severe": "tab:red"}
    for j, (name, (key, label)) in enumerate(_FACTORS.items()):
        for sev, c in colours.items():
            g = [r for r in rows if r["group"] == sev]
            ax[j].scatter([r[key] for r in g if r["detected"]], [max(r["err_max"], 1e-3) for r in g if r["detected"]],
                          s=8, c=c, alpha=0.6, label=sev)
            miss = [r[key] for r in g if not r["detected"]]
            ax[j].scatter(miss, [20.0] * len(miss), marker="x", c=c, s=40)
        ax[j].set_yscale("log")
        ax[j].axhline(_ERR_MAX, color="grey", lw=0.8)
        ax[j].set_xlabel(label)
        ax[j].set_ylabel("worst-corner error (snapshot px); x = missed")
    ax[0].legend()
    fig.suptitle("random preset photos (seeds): corner error against each factor; misses drawn at the top")
    fig.tight_layout()
    fig.savefig(out / "scan_presets.png", dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    sevs = [s for s in colours if any(r["group"] == s and r["detected"] for r in rows)]
    ax.boxplot([[r["psnr"] for r in rows if r["group"] == s and r["detected"]] for s in sevs])
    ax.set_xticks(range(1, len(sevs) + 1), sevs)
    ax.set_ylabel("rectified vs true snapshot PSNR (dB)")
    fig.tight_layout()
    fig.savefig(out / "scan_psnr.png", dpi=90)
    plt.close(fig)
