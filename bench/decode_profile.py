"""`snapshot3d bench decode --profile`: where the time of one decode goes (issue 39's "profile first").

Decodes the bundled example photo (a `moderate` photo of a printed sheet) `repeats` times after one warm-up,
in this process and with the decode's own threads, and writes:
- decode_profile.json: the median time of each stage (scan, restore, bake, render) and its share of the
  decode, the first view, and the functions that took the most time under cProfile (one more decode);
- decode_profile.txt: the same cProfile listing, sorted by internal time and by cumulative time.

cProfile sees only the Python thread that calls it: time spent in onnxruntime's and OpenCV's own threads
shows up as the waiting caller, so the stage medians (wall clock, no profiler) are the figures to read."""
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


def _top(stats: pstats.Stats, key: str, n: int) -> list[dict]:
    """The n functions first by `key` ('tottime' or 'cumtime'), with their calls and seconds."""
    rows = []
    for (file, line, name), (cc, nc, tt, ct, _) in stats.stats.items():
        rows.append({"function": f"{Path(file).name}:{line}({name})", "calls": nc, "tottime_s": round(tt, 4),
                     "cumtime_s": round(ct, 4)})
    return sorted(rows, key=lambda r: -r[f"{key}_s"])[:n]


def profile_decode(out: Path, repeats: int = 5, photo: Path | None = None, top: int = 25) -> dict:
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
           "top_by_tottime": _top(stats, "tottime", top), "top_by_cumtime": _top(stats, "cumtime", top)}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "decode_profile.json", doc)
    (out / "decode_profile.txt").write_text(text.getvalue())
    return doc
