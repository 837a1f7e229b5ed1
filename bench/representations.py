"""`snapshot3d bench fit --representations`: tri-planes against a dense grid, a hash grid and a pure MLP at equal
bytes (issue 37 item 2), on the bench's scenes (spot and lego as `bench fit` loads them), `field_psnr` at their
held-out views. Every field is fitted from scratch with the same rays, steps, occupancy grid, regularisers and
8-bit ending (`train/field/rep_fit.py`); what each carries is counted at one byte per value
(`representations.py`). Speed beside accuracy: each row's fit time and time per held-out view on the device that
fitted it, and the cost of one sample of the 8-bit field on this machine's CPU (`cpu_us_per_ksample`, measured
for every row where the rows are written, so that rows fitted on different devices compare).

Rows are kept per (scene, kind, budget) as they finish (`RowBlocks`), so a killed run resumes. `--merge`
combines the NAME_*.json files of runs split over processes into NAME.*. Writes NAME.{csv,json,png}."""
from __future__ import annotations

import json
import time
from functools import lru_cache
from pathlib import Path

from snapshot3d.errors import UserError

from .common import RowBlocks, pyplot, write_report
from .scenes import checked_scenes, load_bench_scene

__all__ = ["bench_representations_command"]


@lru_cache(maxsize=1)
def _scene(name: str):
    """The bench scene `name` as `bench fit` loads it, once for all the rows of a scene."""
    return load_bench_scene(name)[0]


def _rows(args, scene: str, kind: str, kb: float) -> list[dict]:
    import torch

    from snapshot3d.train.device import resolve_device
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.rep_fit import RepFitConfig, evaluate_representation, fit_representation

    device = resolve_device(args.device)
    posed = _scene(scene)
    cfg = RepFitConfig(steps=args.rep_steps, batch_rays=args.rep_rays)
    field, info = fit_representation(posed, kind, int(kb * 1000), cfg, load_decoder().to(device), device)
    views = posed.test[:args.rep_views] if args.rep_views else posed.test
    ev = evaluate_representation(field, posed, views)
    size = field.size
    return [{"scene": scene, "kind": kind, "budget_kb": kb, "res": size.res, "channels": size.channels,
             "carried_kb": round(info["carried_bytes"] / 1000, 2), "field_psnr": round(ev["field_psnr"], 3),
             "fit_seconds": info["fit_seconds"], "rays_per_s": info["rays_per_s"],
             "render_ms_per_view": ev["render_ms_per_view"], "views": len(views), "steps": cfg.steps,
             "device": str(device) + (f" ({torch.cuda.get_device_name()})" if device.type == "cuda" else "")}]


def _chart(rows: list[dict], path: Path) -> None:
    plt = pyplot()
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    kinds = list(dict.fromkeys(r["kind"] for r in rows))
    fig, axes = plt.subplots(2, len(scenes), figsize=(5.5 * len(scenes), 8.4), squeeze=False)
    for j, scene in enumerate(scenes):
        for i, kind in enumerate(kinds):
            pts = sorted((r["carried_kb"], r["field_psnr"], r["cpu_us_per_ksample"]) for r in rows
                         if r["scene"] == scene and r["kind"] == kind)
            style = dict(color=f"C{i}", marker="o", label=kind, ls="-" if kind.startswith("triplane") else "--")
            axes[0, j].plot([p[0] for p in pts], [p[1] for p in pts], **style)
            axes[1, j].plot([p[2] for p in pts], [p[1] for p in pts], **style)
        axes[0, j].set(xscale="log", xlabel="carried kB (8-bit values)", ylabel="field_psnr at held-out views (dB)",
                       title=f"{scene}: accuracy against bytes")
        axes[1, j].set(xscale="log", xlabel="CPU microseconds per 1000 samples (8-bit field, forward)",
                       ylabel="field_psnr (dB)", title=f"{scene}: accuracy against the cost of a sample")
        for ax in axes[:, j]:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _sample_cost(kind: str, kb: float, repeats: int = 5, n: int = 1 << 16) -> float:
    """Microseconds per 1000 samples of `kind` at `kb` (its 8-bit values, forward only, no gradient) on this
    machine's CPU: what a render pays per sample, whatever device fitted the row."""
    import torch

    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.representations import build_field

    field = build_field(kind, int(kb * 1000), decoder=load_decoder())
    pts = torch.rand(n, 3, generator=torch.Generator().manual_seed(0)) * 2 - 1
    times = []
    with torch.no_grad():
        for _ in range(repeats):
            t0 = time.perf_counter()
            field(pts, True)
            times.append(time.perf_counter() - t0)
    return round(1e9 * sorted(times)[repeats // 2] / n, 1)


def _with_cost(rows: list[dict]) -> list[dict]:
    cost = {}
    for r in rows:
        key = (r["kind"], r["budget_kb"])
        if key not in cost:
            cost[key] = _sample_cost(*key)
        r["cpu_us_per_ksample"] = cost[key]
    return rows


def _merge(out: Path, name: str) -> tuple[list[dict], list[str]]:
    """The rows of every out/NAME_*.json (runs split over processes or machines; each row names its device)."""
    parts = sorted(p for p in out.glob(f"{name}_*.json"))
    if not parts:
        raise UserError(f"--merge: no {name}_*.json in {out}")
    rows = []
    for p in parts:
        rows += json.loads(p.read_text())["rows"]
    return rows, [p.name for p in parts]


def _checked(args) -> tuple[list[float], list[str], list[str]]:
    """The budgets (kB), kinds and scenes asked for; UserError naming the first option that is wrong (an unknown
    kind, or a budget too small for one, included: before anything is fitted or loaded)."""
    from snapshot3d.train.field.rep_sizes import size_for_budget

    try:
        budgets = [float(x) for x in args.budgets_kb.split(",") if x]
    except ValueError:
        raise UserError(f"--budgets-kb must be numbers of kB separated by commas, not {args.budgets_kb!r}") from None
    kinds = [k for k in args.kinds.split(",") if k]
    scenes = checked_scenes(args.scenes)
    for opt, value, least in (("--rep-steps", args.rep_steps, 1), ("--rep-rays", args.rep_rays, 1),
                              ("--rep-views", args.rep_views, 0)):
        if value < least:
            raise UserError(f"{opt} must be >= {least}, not {value}")
    if not (budgets and kinds and scenes) or not all(b > 0 for b in budgets):
        raise UserError("--budgets-kb, --kinds and --scenes must each name at least one, budgets above 0")
    for kind in kinds:
        for kb in budgets:
            size_for_budget(kind, int(kb * 1000))
    return budgets, kinds, scenes


def bench_representations_command(args) -> int:
    if args.quick:   # a smoke run: one small field per kind on spot
        args.scenes, args.budgets_kb, args.rep_steps, args.rep_rays, args.rep_views = "spot", "4", 20, 512, 1
    out, name = Path(args.out), args.rep_name
    budgets, kinds, scenes = _checked(args)
    t0 = time.time()
    parts = None
    if args.merge:
        rows, parts = _merge(out, name)
    else:
        blocks = RowBlocks(out / f".{name}.partial.jsonl",
                           {"scenes": scenes, "kinds": kinds, "budgets": budgets, "steps": args.rep_steps,
                            "rays": args.rep_rays, "views": args.rep_views, "device": args.device})
        rows = []
        for scene in scenes:
            for kb in budgets:
                for kind in kinds:
                    got = blocks.rows(f"{scene}/{kind}/{kb}", lambda: _rows(args, scene, kind, kb))
                    rows += got
                    print(f"{scene} {kind} {kb:g} kB: {got[0]['field_psnr']:.2f} dB, fit {got[0]['fit_seconds']} s "
                          f"({time.time() - t0:.0f} s)", flush=True)
        blocks.finish()
    rows = _with_cost(rows)
    doc = write_report(out, name, rows, {"rows": rows, "seconds": round(time.time() - t0, 1),
                                         **({"merged": parts} if parts else {})})
    _chart(doc["rows"], out / f"{name}.png")
    print(f"wrote {out / name}.csv, .json, .png")
    return 0
