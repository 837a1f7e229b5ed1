"""The chart of `bench codec` (matplotlib, Agg): four panels from codec.csv's rows."""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["write_codec_chart", "break_severity"]

_SEV = ["none", "jpeg90", "jpeg75", "mild", "moderate", "severe"]
BREAK_DB = 20.0
"""a method is broken at the first severity where its median restore_psnr falls below this"""


def _median_by_sev(rows, method):
    out = []
    for s in _SEV:
        vals = [r["restore_psnr"] for r in rows if r["method"] == method and r.get("severity") == s
                and r.get("strength", 1.0) == 1.0 and r.get("restore_psnr") is not None]
        out.append(float(np.median(vals)) if vals else np.nan)
    return out


def break_severity(meds: list) -> int | None:
    for i, v in enumerate(meds):
        if not np.isnan(v) and v < BREAK_DB:
            return i
    return None


def write_codec_chart(rows: list[dict], path: Path, cores: int) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(13, 9))
    a = ax[0, 0]
    for method in dict.fromkeys(r["method"] for r in rows if r["method"] in ("ours", "ours-refined", "digital", "lsb")):
        meds = _median_by_sev(rows, method)
        line, = a.plot(range(len(_SEV)), meds, "o-", label=method)
        b = break_severity(meds)
        if b is not None:
            a.plot([b], [meds[b]], "x", ms=14, mew=3, color=line.get_color())
    a.axhline(BREAK_DB, ls=":", c="grey")
    a.set_xticks(range(len(_SEV)), _SEV)
    a.set_ylabel("restore_psnr (dB), median")
    a.set_title(f"restore vs severity (x: breaks, < {BREAK_DB:.0f} dB)")
    a.legend()

    a = ax[0, 1]
    for sev in ("none", "jpeg75", "moderate"):
        pts = {}
        for r in rows:
            if r["method"] == "strength" and r.get("severity") == sev and r.get("restore_psnr") is not None:
                pts.setdefault(r["strength"], []).append((r["host_psnr"], r["restore_psnr"]))
        if pts:
            xs = sorted(pts)
            hp = [np.median([p[0] for p in pts[s]]) for s in xs]
            rp = [np.median([p[1] for p in pts[s]]) for s in xs]
            a.plot(hp, rp, "o-", label=sev)
            for s, x, y in zip(xs, hp, rp):
                a.annotate(f"{s:g}", (x, y), fontsize=7)
    a.set_xlabel("host_psnr (dB)")
    a.set_ylabel("restore_psnr (dB)")
    a.set_title("embedding strength sweep (labels: strength)")
    a.legend()

    a = ax[1, 0]
    arch = [r for r in rows if r["method"] == "arch"]
    a.plot([r["params"] / 1e3 for r in arch], [r["restore_ms"] for r in arch], "o-")
    for r in arch:
        a.annotate(f"{r['blocks']}x{r['width']}", (r["params"] / 1e3, r["restore_ms"]), fontsize=8)
    a.set_xlabel("codec parameters (thousands)")
    a.set_ylabel("restore ms at 380x380")
    a.set_title(f"codec depth x width: restore time ({cores} cores)")

    a = ax[1, 1]
    for sev in ("none", "jpeg75", "moderate"):
        vr = sorted((r["views"], r.get("carried_psnr"), r.get("uncarried_psnr")) for r in rows
                    if r["method"].startswith("views-") and r.get("severity") == sev)
        if vr:
            line, = a.plot([v[0] for v in vr], [v[1] for v in vr], "o-", label=f"carried views, {sev}")
            a.plot([v[0] for v in vr], [v[2] for v in vr], "s--", color=line.get_color(), label=f"other orbit views, {sev}")
    a.set_xlabel("views carried instead of planes")
    a.set_ylabel("view PSNR (dB)")
    a.set_title("baseline c: fixed views (64x64) instead of planes")
    a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
