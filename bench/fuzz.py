"""`snapshot3d bench fuzz`: a seeded, reproducible campaign of hostile inputs (issue 36) over
(a) the readers and the command lines in process (`snapshot3d.cli.main(argv)`), (b) a few real
`python -m snapshot3d` runs per class (their real stderr and peak RSS) and (c) a live `snapshot3d serve`
on 127.0.0.1 (uploads, query and path parameters, malformed HTTP, slow bodies, overload).

Writes counts per campaign, class and outcome to OUT/fuzz.csv and OUT/fuzz.json (with the date, git
commit, cores, library versions and up to 5 examples per failing class and outcome) and prints a table.
Targets: 0 traceback, 0 5xx (503 is an answer), 0 nonfinite, 0 partial, peak memory <= 2 GB per input
(in process: tracemalloc's peak, which sees Python and numpy allocations but not a C library's own
buffers; the subprocess runs' VmHWM and the server's cover those). Inputs and outcomes:
`bench.fuzz_inputs`, `bench.fuzz_crafted`, `bench.fuzz_misc`, `bench.fuzz_run`, `bench.fuzz_http`."""
from __future__ import annotations

import csv
import json
import os
import sys
import tempfile
import time
import tracemalloc
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

from .common import run_metadata

__all__ = ["bench_fuzz_command", "file_inputs"]

OUTCOMES = ("ok", "error", "traceback", "5xx", "nonfinite", "partial", "multiline", "nonjson", "dropped", "timeout")
BAD = ("traceback", "5xx", "nonfinite", "partial", "multiline", "nonjson")
MEMORY_LIMIT_MB = 2000
ROOT = Path(__file__).resolve().parent.parent


class Tally:
    def __init__(self):
        self.counts: Counter = Counter()
        self.peak: dict = defaultdict(float)
        self.examples: dict = defaultdict(list)

    def add(self, campaign: str, cls: str, outcome: str, detail: str = "", label: str = "", peak_mb: float = 0.0):
        self.counts[(campaign, cls, outcome)] += 1
        self.peak[(campaign, cls)] = max(self.peak[(campaign, cls)], peak_mb)
        if outcome not in ("ok", "error") or peak_mb > MEMORY_LIMIT_MB:
            ex = self.examples[f"{campaign}/{cls}/{outcome}"]
            if len(ex) < 5:
                ex.append(f"{label}: {detail}"[:300])

    def rows(self) -> list[dict]:
        keys = sorted({(c, k) for c, k, _ in self.counts})
        out = []
        for campaign, cls in keys:
            row = {"campaign": campaign, "class": cls}
            row.update({o: self.counts[(campaign, cls, o)] for o in OUTCOMES})
            row["inputs"] = sum(row[o] for o in OUTCOMES)
            row["peak_mb"] = round(self.peak[(campaign, cls)], 1)
            out.append(row)
        return out


_WORK: dict = {}
"""the inputs and their folder, set before the workers fork (they inherit it, nothing is pickled)"""


def _worker_start() -> None:
    tracemalloc.start()


def _worker_run(i: int) -> tuple[int, dict]:
    from .fuzz_run import run_inprocess
    return i, run_inprocess(_WORK["inputs"][i], _WORK["root"])


def _in_process(inputs, tally, root, say, workers: int) -> float:
    """Every input in `workers` forked processes (each its own tracemalloc), results in input order."""
    import multiprocessing
    t0 = time.perf_counter()
    _WORK.update(inputs=inputs, root=root)
    results = [None] * len(inputs)
    with multiprocessing.get_context("fork").Pool(workers, initializer=_worker_start, maxtasksperchild=500) as pool:
        for n, (i, r) in enumerate(pool.imap_unordered(_worker_run, range(len(inputs)), chunksize=8)):
            results[i] = r
            if (n + 1) % 1000 == 0:
                say(f"  in process: {n + 1}/{len(inputs)} ({time.perf_counter() - t0:.0f} s)")
    for inp, r in zip(inputs, results):
        tally.add("in-process", inp.cls, r["outcome"], r["detail"], inp.label, r["peak_mb"])
    return time.perf_counter() - t0


def _subprocesses(inputs, tally, root, per_class: int) -> float:
    from .fuzz_run import run_subprocess
    t0, taken = time.perf_counter(), Counter()
    for inp in inputs:
        if inp.argv and taken[inp.cls] < per_class:
            taken[inp.cls] += 1
            r = run_subprocess(inp, root)
            tally.add("subprocess", inp.cls, r["outcome"], r["detail"], " ".join(inp.argv[:1]) + " " + inp.label,
                      r["peak_mb"])
    return time.perf_counter() - t0


def _serve(seeds, inputs, tally, rng, scale, root) -> tuple[float, float]:
    from .fuzz_http import Live
    from .fuzz_http_cases import http_campaign
    t0 = time.perf_counter()
    with Live(root) as live:
        http_campaign(live, seeds, inputs, rng, scale, lambda cls, outcome, detail="": tally.add(
            "serve", cls, outcome, detail, cls))
        alive = live.request("GET", "/healthz")[0] == 200
        peak = live.peak_mb()
    lines = live.log_text().splitlines()
    tally.add("serve", "server_alive_at_end", "ok" if alive else "dropped")
    for line in lines:
        if "Traceback" in line:
            tally.add("serve", "server_log", "traceback", line, "serve.log")
    tally.peak[("serve", "server_log")] = peak
    other = sorted({ln[:160] for ln in lines if " -> " not in ln and "went away" not in ln})
    log = {"lines": len(lines), "refusal_lines": sum(" -> " in ln for ln in lines), "other_lines": other[:15]}
    return time.perf_counter() - t0, peak, log


def file_inputs(seeds, rng, scale: float) -> list:
    """Every file-based class (readers in process and command lines), `scale` x the default counts."""
    from .fuzz_crafted import images, metadata, scenes, warnings_class
    from .fuzz_misc import misc
    return [x for make in (images, warnings_class, metadata, scenes, misc) for x in make(seeds, rng, scale)]


def bench_fuzz_command(args) -> int:
    from .fuzz_inputs import Seeds
    quick = bool(getattr(args, "quick", False))
    scale = 0.03 if quick else args.scale
    rng = np.random.default_rng(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    os.environ["SNAPSHOT3D_PROGRESS"] = "0"
    say = print
    t_start = time.perf_counter()
    seeds = Seeds(ROOT)
    inputs = file_inputs(seeds, rng, scale)
    if quick:  # a smoke run: a seeded sample of every class
        by_cls = defaultdict(list)
        for x in inputs:
            by_cls[x.cls].append(x)
        inputs = [x for xs in by_cls.values() for x in xs[:: max(1, len(xs) // 12)][:12]]
    say(f"bench fuzz: {len(inputs)} inputs in process (seed {args.seed}, scale {scale:g})")
    tally = Tally()
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        root = Path(tmp) / "inputs"
        root.mkdir()
        secs = {"in_process": _in_process(inputs, tally, root, say, max(1, min(args.workers, os.cpu_count() or 1)))}
        say(f"  in process: {secs['in_process']:.0f} s; now command lines as subprocesses")
        secs["subprocess"] = _subprocesses(inputs, tally, root, 1 if quick else args.per_class)
        say(f"  subprocesses: {secs['subprocess']:.0f} s; now the live server")
        serve_root = Path(tmp) / "serve"
        serve_root.mkdir()
        secs["serve"], server_peak, server_log = _serve(seeds, inputs, tally, rng, scale, serve_root)
    secs["total"] = time.perf_counter() - t_start
    rows = tally.rows()
    totals = {o: sum(r[o] for r in rows) for o in OUTCOMES}
    totals["inputs"] = sum(r["inputs"] for r in rows)
    totals["max_peak_mb"] = max((r["peak_mb"] for r in rows), default=0)
    report = {"meta": run_metadata(), "command": "snapshot3d " + " ".join(sys.argv[1:]), "seed": args.seed, "scale": scale, "quick": quick,
              "seconds": {k: round(v, 1) for k, v in secs.items()}, "server_peak_rss_mb": round(server_peak, 1),
              "server_log": server_log,
              "totals": totals, "targets_met": all(totals[o] == 0 for o in BAD)
              and totals["max_peak_mb"] <= MEMORY_LIMIT_MB, "rows": rows, "examples": dict(tally.examples)}
    (out / "fuzz.json").write_text(json.dumps(report, indent=1) + "\n")
    with open(out / "fuzz.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ["campaign", "class", "inputs", *OUTCOMES, "peak_mb"])
        w.writeheader()
        w.writerows(rows)
    _table(rows, totals, say)
    say(f"bench fuzz: {totals['inputs']} inputs in {secs['total']:.0f} s; targets "
        f"{'met' if report['targets_met'] else 'NOT met'}; wrote {out / 'fuzz.csv'} and {out / 'fuzz.json'}")
    return 0


def _table(rows, totals, say) -> None:
    cols = ["inputs", *OUTCOMES, "peak_mb"]
    say(f"{'campaign':<11}{'class':<22}" + "".join(f"{c[:9]:>10}" for c in cols))
    for r in rows:
        say(f"{r['campaign']:<11}{r['class'][:21]:<22}" + "".join(f"{r[c]:>10}" for c in cols))
    say(f"{'total':<33}" + "".join(f"{totals.get(c, ''):>10}" for c in cols[:-1]) + f"{totals['max_peak_mb']:>10}")
