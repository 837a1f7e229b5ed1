"""`snapshot3d bench decode --profile`: where the time of one decode goes (issue 39's "profile first").

Decodes the bundled example photo (a `moderate` photo of a printed sheet) `repeats` times after one warm-up,
in this process and with the decode's own threads, and writes:
- decode_profile.json: the median time of each stage (scan, restore, bake, render) and its share of the
  decode, the first view, and the functions that took the most time under cProfile (one more decode);
- decode_profile.txt: the same cProfile listing, sorted by internal time and by cumulative time.

cProfile sees only the Python thread that calls it: time spent in onnxruntime's and OpenCV's own threads
shows up as the waiting caller, so the stage medians (wall clock, no profiler) are the figures to read.

Cold decodes (`cold` > 0) run `snapshot3d decode` in a fresh process each, as a user's first decode does
(models loaded, OpenCV's and numpy's first calls), and read its report.json. decode_profile.png charts
the stages before (the figures issue 39 was filed with, BEFORE) and now."""
from __future__ import annotations

import cProfile
import io
import pstats
import statistics
from pathlib import Path

from snapshot3d.paths import asset
from snapshot3d.reports import write_json

from .common import run_metadata

__all__ = ["profile_decode", "STAGES"]

STAGES = ("scan", "restore", "bake", "render")
BEFORE = {  # issue 39 as filed: `snapshot3d demo` of the example photo, 2 cores, medians of 3 runs
    "cold": {"stages_ms": {"scan": 370, "restore": 116, "bake": 205, "render": 992}, "decode_ms": 1683,
             "first_view_ms": 793},
    "warm": {"stages_ms": None, "decode_ms": 1304, "first_view_ms": 616},
}


def _top(stats: pstats.Stats, key: str, n: int) -> list[dict]:
    """The n functions first by `key` ('tottime' or 'cumtime'), with their calls and seconds."""
    rows = []
    for (file, line, name), (cc, nc, tt, ct, _) in stats.stats.items():
        rows.append({"function": f"{Path(file).name}:{line}({name})", "calls": nc, "tottime_s": round(tt, 4),
                     "cumtime_s": round(ct, 4)})
    return sorted(rows, key=lambda r: -r[f"{key}_s"])[:n]


def cold_decodes(photo: Path, n: int) -> list[dict]:
    """n decodes of `photo`, each by `snapshot3d decode` in a fresh process -> their reports' timings_ms
    (stages and first_view) and decode_ms."""
    import json
    import subprocess
    import sys
    import tempfile

    runs = []
    for _ in range(n):
        with tempfile.TemporaryDirectory(prefix="s3d-cold-") as tmp:
            subprocess.run([sys.executable, "-m", "snapshot3d", "decode", str(photo), "-o", tmp], check=True,
                           stdout=subprocess.DEVNULL)
            report = json.loads((Path(tmp) / "report.json").read_text())
        runs.append({**report["timings_ms"], "decode_ms": report["decode_ms"]})
    return runs


def _median_run(runs: list[dict]) -> dict:
    return {"stages_ms": {s: round(statistics.median(r[s] for r in runs), 1) for s in STAGES},
            "decode_ms": round(statistics.median(r["decode_ms"] for r in runs), 1),
            "first_view_ms": round(statistics.median(r["first_view"] for r in runs), 1)}


def chart_stages(path: Path, doc: dict) -> None:
    """Stacked bars of the stages' medians: before (BEFORE) and now, cold and warm; first view as a mark."""
    from .common import pyplot

    plt = pyplot()
    bars = [("cold, filed", BEFORE["cold"]), ("cold, now", doc.get("cold")), ("warm, filed", BEFORE["warm"]),
            ("warm, now", {"stages_ms": doc["stages_ms_median"], "decode_ms": doc["decode_ms_median"],
                           "first_view_ms": doc["first_view_ms_median"]})]
    bars = [(name, b) for name, b in bars if b]
    fig, ax = plt.subplots(figsize=(9, 0.7 * len(bars) + 1.6))
    for y, (name, b) in enumerate(bars):
        left = 0.0
        for k, s in enumerate(STAGES):
            if b["stages_ms"] is None:
                break
            v = b["stages_ms"][s]
            ax.barh(y, v, left=left, color=f"C{k}", label=s if y == 0 else None)
            left += v
        if b["stages_ms"] is None:
            ax.barh(y, b["decode_ms"], color="0.7", label="total only (no stages filed)")
        ax.plot(b["first_view_ms"], y, "k|", ms=22, mew=2, label="first view" if y == 0 else None)
        ax.text(max(left, b["decode_ms"]) + 15, y, f"{b['decode_ms']:.0f} ms", va="center")
    ax.axvline(1000, color="C3", ls="--", lw=1, label="target 20 views")
    ax.axvline(300, color="C3", ls=":", lw=1, label="target first view")
    ax.set_yticks(range(len(bars)), [n for n, _ in bars])
    ax.invert_yaxis()
    ax.set(xlabel=f"ms, example photo to 20 views of 380x380 ({doc['meta']['cores']} cores, medians)",
           title="decode: time per stage when issue 39 was filed and now")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def profile_decode(out: Path, repeats: int = 5, photo: Path | None = None, top: int = 25, cold: int = 0) -> dict:
    """Profile decodes of `photo` (default the example photo) into out/decode_profile.{json,txt}; returns the doc."""
    from snapshot3d.viewer.decode import decode_photo

    photo = Path(photo or asset("example-photo.jpg"))
    decode_photo(photo)   # warm-up: onnxruntime sessions, OpenCV's first calls, numpy's caches
    runs = [decode_photo(photo).report for _ in range(max(int(repeats), 1))]
    median = {s: statistics.median(r["timings_ms"][s] for r in runs) for s in STAGES}
    total = statistics.median(r["decode_ms"] for r in runs)
    prof = cProfile.Profile()
    prof.enable()
    decode_photo(photo)
    prof.disable()
    stats = pstats.Stats(prof)
    text = io.StringIO()
    for key in ("tottime", "cumulative"):
        pstats.Stats(prof, stream=text).sort_stats(key).print_stats(top)
    doc = {"meta": run_metadata(), "photo": photo.name, "repeats": len(runs),
           "decode_ms_median": round(total, 1),
           "first_view_ms_median": round(statistics.median(r["timings_ms"]["first_view"] for r in runs), 1),
           "stages_ms_median": {s: round(v, 1) for s, v in median.items()},
           "stages_share": {s: round(v / total, 3) for s, v in median.items()},
           "other_ms": round(total - sum(median.values()), 1),
           "top_by_tottime": _top(stats, "tottime", top), "top_by_cumtime": _top(stats, "cumtime", top),
           "before": BEFORE}
    if cold > 0:
        doc["cold"] = _median_run(cold_decodes(photo, cold))
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "decode_profile.json", doc)
    chart_stages(out / "decode_profile.png", doc)
    (out / "decode_profile.txt").write_text(text.getvalue())
    return doc
