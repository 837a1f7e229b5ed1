"""`snapshot3d bench refine`: embed-time refinement of a file snapshot, its time against what a user gets.
A scene is marked and hidden in a host as `embed --medium file` does it (`scanner.pixelmeta`, then the
invertible codec), refined N steps by a schedule (`train.codec.refine.SCHEDULES`: the shipped `turns` at
several step counts, and the former `both-weighted`), written as `embed` writes it (`formats.FILE_SCALE`
times its size) and read back as a user would: from the PNG, from a JPEG-75 copy and from a 256-px copy, each with no text (metadata from the pixels, `scanner.snapfile`;
restore in onnxruntime, `viewer.media`).

Rows (refine.csv), per scene, host, schedule and step count: `refine_s` (the refinement's wall time on
this machine), `host_psnr` (against the unmarked host), `restore_psnr` of each copy (20 orbit views at
128x128 of the restored planes against the original planes'). Writes refine.{csv,json,png}: the JSON's
summary has medians per schedule and step count; the chart puts `restore_psnr` against `refine_s`."""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.snapfile import file_pixels, snapshot_in_image
from snapshot3d.scene import load_scene_file
from snapshot3d.viewer.media import restore_planes

from .common import RowBlocks, ViewJudge, median, psnr, pyplot, write_report
from .sharing import SHARING

__all__ = ["bench_refine_command", "COPIES"]

COPIES = ("png", "jpeg75", "256 px")
"""the copies each snapshot is read from (`bench.sharing.SHARING` names)"""
SIZE = 128


def _rows(net, scene, sname: str, hname: str, host: np.ndarray, judge: ViewJudge,
          runs: list[tuple[str, int, str]]) -> list[dict]:
    from snapshot3d.train.codec.embedding import marked_host, strength_for
    from snapshot3d.train.codec.hinet import embed_planes
    from snapshot3d.train.codec.refine import refine_snapshot

    host8 = (np.clip(host, 0, 1) * 255 + 0.5).astype(np.uint8)
    strengths = {x: strength_for("file", host, scene, float(x[:-3])) if x.endswith(" dB") else float(x[1:])
                 for x in dict.fromkeys(x for _, _, x in runs)}   # each setting's strength, found once
    rows = []
    for schedule, steps, setting in runs:
        strength = strengths[setting]
        marked = marked_host(host, scene, strength)
        t = time.perf_counter()
        snap = (refine_snapshot(net, marked, scene.planes(), steps, strength, schedule=schedule)[0] if steps
                else embed_planes(net, marked, scene.planes(), strength))
        row = {"scene": sname, "host": hname, "schedule": schedule, "steps": steps, "setting": setting,
               "strength": strength,
               "refine_s": time.perf_counter() - t, "host_psnr": psnr(snap / 255, host8 / 255)}
        for name in COPIES:
            got = snapshot_in_image("copy", SHARING[name][0](file_pixels(snap, formats.FILE_SCALE),
                                                             np.random.default_rng(0)), None)
            row[name] = judge.planes_psnr(restore_planes(got[0], got[1])[0]) if got is not None else None
        rows.append(row)
        print(f"{sname} / {hname} / {schedule} {steps} {setting} (x{strength:g}): {row['refine_s']:.1f} s, host {row['host_psnr']:.2f}, "
              + ", ".join(f"{k} {row[k]:.2f}" for k in COPIES if row[k] is not None), flush=True)
    return rows


def _summary(rows: list[dict]) -> list[dict]:
    def key(r: dict) -> tuple:
        return r["schedule"], r["steps"], r.get("setting", "x1")

    return [{"schedule": s, "steps": n, "setting": x, **{k: median([r for r in rows if key(r) == (s, n, x)], k)
                                                         for k in ("refine_s", "strength", "host_psnr", *COPIES)}}
            for s, n, x in dict.fromkeys(key(r) for r in rows)]


def _chart(summary: list[dict], path: Path, cores: int) -> None:
    """Top row: restore_psnr against refinement time at strength 1; bottom row (when host fidelity was swept):
    restore_psnr against host_psnr, unrefined and refined."""
    plt = pyplot()
    swept = len({p["setting"] for p in summary}) > 1
    fig, axes = plt.subplots(1 + swept, len(COPIES), figsize=(5 * len(COPIES), 4 * (1 + swept)), squeeze=False)
    for ax, copy in zip(axes[0], COPIES):
        for schedule, marker in (("turns", "o-"), ("both-weighted", "s--")):
            pts = [p for p in summary if p["schedule"] in (schedule, "none") and p["setting"] == "x1"
                   and p[copy] is not None]
            if pts:
                ax.plot([p["refine_s"] for p in pts], [p[copy] for p in pts], marker, label=schedule)
                for p in pts:
                    ax.annotate(str(p["steps"]), (p["refine_s"], p[copy]), fontsize=7, xytext=(3, 3),
                                textcoords="offset points")
        ax.set_xlabel(f"refinement time (s, {cores} cores)")
        ax.set_ylabel("restore_psnr (dB), median")
        ax.set_title(f"file snapshot, read from: {copy}")
        ax.legend(loc="lower right", fontsize=8)
    for ax, copy in zip(axes[1] if swept else (), COPIES):
        for steps, marker in sorted({(p["steps"], "o-" if p["steps"] else "s--") for p in summary
                                     if p["schedule"] in ("turns", "none")}):
            pts = sorted((p for p in summary if p["schedule"] in ("turns", "none") and p["steps"] == steps
                          and p[copy] is not None), key=lambda p: p["host_psnr"])
            ax.plot([p["host_psnr"] for p in pts], [p[copy] for p in pts], marker, label=f"{steps} steps")
            for p in pts:
                ax.annotate(p["setting"], (p["host_psnr"], p[copy]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")
        ax.set_xlabel("host_psnr (dB), median")
        ax.set_ylabel("restore_psnr (dB), median")
        ax.set_title(f"host fidelity sweep, read from: {copy}")
        ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _setting(text: str) -> str:
    """'0.55' -> 'x0.55' (an embed strength); '38dB' -> '38 dB' (a host fidelity, `embed --host-psnr`)."""
    from snapshot3d.train.codec.commands import HOST_PSNRS
    from snapshot3d.train.codec.embedding import STRENGTHS

    t = text.strip()
    try:
        value = float(t[:-2] if t.lower().endswith("db") else t)
    except ValueError:
        raise UserError(f"--strengths takes comma-separated strengths or host PSNRs (like 38dB), not {t!r}") from None
    if t.lower().endswith("db"):
        if not HOST_PSNRS[0] <= value <= HOST_PSNRS[1]:
            raise UserError("a host PSNR of --strengths must be in [{:g}, {:g}] dB, not {!r}".format(*HOST_PSNRS, t))
        return f"{value:g} dB"
    if not STRENGTHS[0] <= value <= STRENGTHS[1]:
        raise UserError("--strengths must be in [{:g}, {:g}], not {!r}".format(*STRENGTHS, t))
    return f"x{value:g}"


def bench_refine_command(args) -> int:
    from .codec_print import heldout_hosts

    try:
        steps = [int(s) for s in args.steps.split(",") if s.strip()]
    except ValueError:
        raise UserError(f"--steps takes comma-separated step counts, not {args.steps!r}") from None
    if not steps or min(steps) < 0 or args.former < 0:
        raise UserError("--steps needs at least one step count, and step counts are >= 0")
    settings = [_setting(x) for x in args.strengths.split(",") if x.strip()]
    if args.strength_steps < 1:
        raise UserError("--strength-steps must be >= 1")
    runs = [("none" if n == 0 else "turns", n, "x1") for n in steps]
    runs += [("both-weighted", args.former, "x1")] if args.former else []
    runs += [(sched, n, x) for x in settings if x != "x1"
             for sched, n in (("none", 0), ("turns", args.strength_steps))]
    scenes = [p for p in args.scenes.split(",") if p]
    missing = [p for p in scenes if not Path(p).is_file()]
    if missing or not scenes:
        raise UserError(f"no scene file {', '.join(missing) or '(none given)'}")
    hosts = {h: load_host("builtin:" + h) for h in args.hosts.split(",") if h}
    hosts.update({Path(p).stem: load_host(p) for p in heldout_hosts(args.heldout)})
    from snapshot3d.train.codec.hinet import load_codec

    net, out, t0, rows = load_codec()[0], Path(args.out), time.time(), []
    blocks = RowBlocks(out / "refine.partial.jsonl", {"scenes": scenes, "hosts": list(hosts), "runs": runs})
    for path in scenes:
        scene, sname = load_scene_file(path), Path(path).stem
        judge = ViewJudge(scene, SIZE)
        for hname, host in hosts.items():
            rows += blocks.rows(f"{sname}/{hname}", lambda: _rows(net, scene, sname, hname, host, judge, runs))
    summary = _summary(rows)
    write_report(out, "refine", rows, {"scenes": [Path(p).stem for p in scenes], "hosts": list(hosts),
                                       "view_size": SIZE, "copies": list(COPIES),
                                       "shipped_steps": formats.FILE_REFINE_STEPS,
                                       "seconds": round(time.time() - t0, 1), "summary": summary})
    _chart(summary, out / "refine.png", os.cpu_count())
    blocks.finish()
    for p in summary:
        print(p)
    return 0
