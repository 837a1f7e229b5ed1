"""The chart of `snapshot3d bench capacity` (matplotlib, Agg): left, `restore_psnr` per severity,
measured with the shipped codec against the best the channel's capacity allows, per plane size, with
issue 4's targets; right, the channel's capacity per severity at each host-fidelity target against the
scenes' sizes."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .codec_bench_run import SEVERITIES, TARGETS

__all__ = ["write_capacity_chart"]


def write_capacity_chart(bounds: dict, path: Path, cores: int) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 6.2))
    xs = np.arange(len(SEVERITIES))
    for i, (sname, b) in enumerate(bounds.items()):
        per = b["by_severity"]
        sev = [s for s in SEVERITIES if s in per]
        x = [SEVERITIES.index(s) for s in sev]
        colour = f"C{i}"
        ax.plot(x, [per[s]["measured_restore_psnr"] for s in sev], "o-", color=colour,
                label=f"{sname} ({b['values'] // 1000}k values): shipped codec")
        ax.plot(x, [per[s]["best_restore_psnr"] for s in sev], "s--", color=colour, alpha=0.7,
                label=f"{sname}: best any codec (capacity bound)")
        if i == 0:
            ax.plot(x, [per[s]["measured_restore_psnr_oracle_scan"] for s in sev], "^:", color=colour, alpha=0.8,
                    label=f"{sname}: shipped codec, perfect scanner (oracle registration + tone)")
    for s, t in TARGETS.items():
        ax.plot(SEVERITIES.index(s), t["restore_psnr"], "k_", markersize=22, markeredgewidth=2)
    ax.plot([], [], "k_", markersize=12, markeredgewidth=2, label="issue 4 target")
    ax.set_xticks(xs, SEVERITIES)
    ax.set_ylabel("restore_psnr (dB), 20 views at 128x128")
    ax.set_title("measured vs the channel's Gaussian capacity bound")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2)
    first = next(iter(bounds.values()))["by_severity"]
    sev = [s for s in SEVERITIES if s in first]
    for j, h in enumerate(("38", "34", "30")):
        bx.plot([SEVERITIES.index(s) for s in sev], [first[s]["capacity_kb_all_targets"][h] for s in sev], "o-",
                color=f"C{j + 3}", label=f"capacity at host {h} dB")
    for i, (sname, b) in enumerate(bounds.items()):
        bx.axhline(b["values"] / 1000.0, color=f"C{i}", ls=":", label=f"{sname}: {b['values'] // 1000} kB at 8 bits/value")
    bx.set_yscale("log")
    bx.set_xticks(xs, SEVERITIES)
    bx.set_ylabel("kB per 380x380 snapshot")
    bx.set_title(f"what the capture channel can carry ({cores} cores)")
    bx.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
