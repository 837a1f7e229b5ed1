"""`snapshot3d bench capture-summary`: issue 40's two targets by the medians over fit seeds, read from the
results files of `bench capture-background` (no fitting). Each capture (mesh, capture seed, walk's arc, pose
noise) and setting of `--seen-ground-weight` gets the medians of its fits' object PSNR and opacity outside the
true mask + 2 px; the masked fits of the same capture give the bound. One fit that appears in two files (the
same capture, setting and fit seed) counts once."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from snapshot3d.errors import UserError

from .capture_background import MODES
from .common import pyplot, run_metadata, write_rows

__all__ = ["GAP_DB", "OUTSIDE", "fit_rows", "summary_rows", "bench_capture_summary_command"]

GAP_DB = -1.5     # the object within 1.5 dB of the masked fit (issue 40)
OUTSIDE = 0.02    # at most 2% of the opacity outside the true mask + 2 px


# score_object's object_{part}_psnr where the rows carry them (since 2026-12-07): the object's pixels along its
# outline and inside it, and the same three against the object alone over white (clean)
_PARTS = ("ring", "inner", "clean", "clean_ring", "clean_inner")
# score_object's edge_split where the rows carry them (since 2026-12-07, later): the opacity just outside the true mask
# where the ground near the object lies behind it and elsewhere, and the near ground's share of it
_EDGES = ("edge_opacity_near", "edge_opacity_far", "edge_near_share")
# the modes that differ from `outer` by --seen-ground-weight alone: one setting each, by the weight
_WEIGHT_ONLY = ("outer", "outer-noseen", "outer-seen", "outer-seen-03", "outer-seen-1")


def _setting(row: dict) -> tuple[str, float] | None:
    """The row's fit as (variant, --seen-ground-weight): the variant is `outer` for the modes that differ from it by
    the weight alone (`outer-spare` where the row says the penalty spared the object's cells, `fit
    --seen-ground-spare`), else the mode's own name; the weight the row's own record, else its mode's setting, else
    0 (rows written before the option existed). ("masked", nan) for the masked bound; None for a fit that is
    neither (white, the refining modes' masked fits)."""
    mode = row["mode"]
    if mode == "masked":
        return ("masked", float("nan"))
    if mode not in MODES or MODES[mode][1] != "outer":
        return None
    weight = row.get("seen_ground_weight")
    weight = float(MODES[mode][3].get("seen_ground_weight", 0.0)) if weight is None else float(weight)
    if mode not in _WEIGHT_ONLY:
        return (mode, weight)
    return ("outer-spare" if row.get("seen_ground_spare") else "outer", weight)


def fit_rows(paths: list[Path]) -> list[dict]:
    """The fits of `paths` (capture-background JSON), each with its capture's key and setting, duplicates
    dropped; a one-line error for a file that is not such a result."""
    fits, seen = [], set()
    for path in paths:
        try:
            report = json.loads(Path(path).read_text())
            capture, rows = report["capture"], report["rows"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise UserError(f"{path}: not a bench capture-background result ({type(exc).__name__}: {exc})") from None
        for row in rows:
            setting = _setting(row)
            if setting is None:
                continue
            key = (row["mesh"], capture["seed"], float(capture.get("arc_deg", 720.0)),
                   float(capture.get("pose_noise_deg", 0.0)), float(capture.get("pose_noise_frac", 0.0)))
            fit_seed = row.get("fit_seed", capture["seed"])
            if (key, setting[0], str(setting[1]), fit_seed) in seen:
                continue
            seen.add((key, setting[0], str(setting[1]), fit_seed))
            fits.append({"key": key, "variant": setting[0], "weight": setting[1], "fit_seed": fit_seed,
                         "object_psnr": row["object_psnr"], "outside": row["opacity_outside_2px"],
                         **{k: row.get(f"object_{k}_psnr") for k in _PARTS}, **{k: row.get(k) for k in _EDGES}})
    return fits


def summary_rows(fits: list[dict]) -> list[dict]:
    """One row per capture, variant and weight: the fits' seeds, the medians, the masked bound and the two
    targets. Captures without a masked fit get no gap. The _PARTS (`_parts`: the object's pixels along its
    outline and inside it, and all three against the object alone over white, with the clean gap) are the
    medians of the fits that carry them, else None."""
    rows = []
    for key in dict.fromkeys(f["key"] for f in fits):
        masked = [f for f in fits if f["key"] == key and f["variant"] == "masked"]
        bound = _median(masked, "object_psnr")
        settings = dict.fromkeys((f["variant"], f["weight"]) for f in fits if f["key"] == key and
                                 f["variant"] != "masked")
        for variant, w in sorted(settings):
            mine = [f for f in fits if f["key"] == key and (f["variant"], f["weight"]) == (variant, w)]
            psnr = _median(mine, "object_psnr")
            outside = float(np.median([f["outside"] for f in mine]))
            gap = None if bound is None else psnr - bound
            rows.append({"mesh": key[0], "capture_seed": key[1], "arc_deg": key[2], "pose_noise_deg": key[3],
                         "pose_noise_frac": key[4], "variant": variant, "seen_ground_weight": w, "fits": len(mine),
                         "fit_seeds": ";".join(str(f["fit_seed"]) for f in mine),
                         "object_psnr": round(psnr, 2), "masked_psnr": None if bound is None else round(bound, 2),
                         "gap_db": None if gap is None else round(gap, 2),
                         "within_gap": None if gap is None else bool(gap >= GAP_DB),
                         "outside": round(outside, 4), "within_outside": bool(outside <= OUTSIDE),
                         "object_psnr_fits": ";".join(f"{f['object_psnr']:.2f}" for f in mine),
                         "outside_fits": ";".join(f"{f['outside']:.4f}" for f in mine),
                         **_parts(mine, masked), **_edges(mine, masked)})
    return rows


def _parts(mine: list[dict], masked: list[dict]) -> dict:
    """The _PARTS medians of the fits `mine` and of the `masked` bound ({part}_psnr, {part}_masked_psnr), and the
    clean gap and its target (clean_gap_db, within_clean_gap); None where the fits do not carry them."""
    out = {f"{k}{m}_psnr": _median(fs, k) for k in _PARTS for m, fs in (("", mine), ("_masked", masked))}
    gap = None if None in (out["clean_psnr"], out["clean_masked_psnr"]) else out["clean_psnr"] - out["clean_masked_psnr"]
    return {**{k: _rounded(v) for k, v in out.items()}, "clean_gap_db": _rounded(gap),
            "within_clean_gap": None if gap is None else bool(gap >= GAP_DB)}


def _edges(mine: list[dict], masked: list[dict]) -> dict:
    """The _EDGES medians of the fits `mine` and of the masked bound ({key}, {key}_masked), rounded to 1e-3; None
    where the fits do not carry them."""
    return {f"{k}{m}": None if (v := _median(fs, k)) is None else round(v, 3)
            for k in _EDGES for m, fs in (("", mine), ("_masked", masked))}


def _median(fits: list[dict], key: str) -> float | None:
    """Median of `key` over the fits that carry it; None where none does."""
    values = [f[key] for f in fits if f.get(key) is not None]
    return float(np.median(values)) if values else None


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(value, 2)


def _label(variant: str, weight: float) -> str:
    """The weight, and the variant where it is not plain `outer`: "0.3", "0.3 (outer-ground256)"."""
    return f"{weight:g}" if variant == "outer" else f"{weight:g} ({variant})"


def _totals(rows: list[dict]) -> dict:
    """Per setting (the weight, with the variant's name where it is not plain `outer`): captures, and how many
    meet each target and both."""
    out = {}
    for variant, w in sorted({(r["variant"], r["seen_ground_weight"]) for r in rows}):
        mine = [r for r in rows if (r["variant"], r["seen_ground_weight"]) == (variant, w)]
        out[_label(variant, w)] = {"captures": len(mine), "within_gap": sum(bool(r["within_gap"]) for r in mine),
                                   "within_outside": sum(r["within_outside"] for r in mine),
                                   "both": sum(bool(r["within_gap"]) and r["within_outside"] for r in mine),
                                   # against the object alone over white, of the captures scored so
                                   "clean_captures": sum(r["within_clean_gap"] is not None for r in mine),
                                   "within_clean_gap": sum(bool(r["within_clean_gap"]) for r in mine),
                                   "both_clean": sum(bool(r["within_clean_gap"]) and r["within_outside"] for r in mine),
                                   "median_fits": float(np.median([r["fits"] for r in mine]))}
    return out


def _chart(path: Path, rows: list[dict]) -> None:
    """Gap to the masked fit against the opacity outside, one point per capture and weight, each capture's
    settings joined by a line; the targets as dashed lines."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    caps = dict.fromkeys((r["mesh"], r["capture_seed"], r["arc_deg"]) for r in rows if r["gap_db"] is not None)
    for cap in caps:
        mine = sorted((r for r in rows if (r["mesh"], r["capture_seed"], r["arc_deg"]) == cap and
                       r["gap_db"] is not None), key=lambda r: (r["variant"], r["seen_ground_weight"]))
        ax.plot([100 * r["outside"] for r in mine], [r["gap_db"] for r in mine], color="0.7", lw=1, zorder=1)
        ax.annotate(f"{cap[0]} s{cap[1]} {cap[2]:g}°", (100 * mine[-1]["outside"], mine[-1]["gap_db"]), fontsize=7,
                    xytext=(3, 3), textcoords="offset points")
    for (variant, w), marker in zip(sorted({(r["variant"], r["seen_ground_weight"]) for r in rows}), "osD^v<>ph"):
        mine = [r for r in rows if (r["variant"], r["seen_ground_weight"]) == (variant, w) and r["gap_db"] is not None]
        ax.scatter([100 * r["outside"] for r in mine], [r["gap_db"] for r in mine], marker=marker, zorder=2,
                   label=f"--seen-ground-weight {_label(variant, w)}")
    ax.axhline(GAP_DB, ls="--", color="k", lw=0.8)
    ax.axvline(100 * OUTSIDE, ls="--", color="k", lw=0.8)
    ax.set_xlabel("opacity outside the true mask + 2 px (%), median over fit seeds")
    ax.set_ylabel("object PSNR minus the masked fit's (dB), median")
    ax.set_title("frontal and full walks without masks: the targets are up and left of the dashes", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def bench_capture_summary_command(args) -> int:
    paths = [Path(p) for p in args.files]
    for p in paths:
        if not p.is_file():
            raise UserError(f"{p}: no such results file")
    rows = summary_rows(fit_rows(paths))
    out = Path(args.out or "bench/results")
    out.mkdir(parents=True, exist_ok=True)
    report = {"meta": run_metadata(), "files": [p.name for p in paths], "gap_db": GAP_DB, "outside": OUTSIDE,
              "totals": _totals(rows), "rows": rows}
    (out / f"{args.name}.json").write_text(json.dumps(report, indent=1))
    write_rows(out / f"{args.name}.csv", rows)
    _chart(out / f"{args.name}.png", rows)
    for r in rows:
        gap = "" if r["gap_db"] is None else f", gap {r['gap_db']:+.2f}"
        if r["ring_psnr"] is not None:
            gap += f" (outline {r['ring_psnr']:.2f}, inside {r['inner_psnr']:.2f})"
        if r["clean_gap_db"] is not None:
            gap += f", on white {r['clean_psnr']:.2f} dB, gap {r['clean_gap_db']:+.2f}"
        if r["edge_opacity_near"] is not None:
            gap += f", edge opacity over the near ground {r['edge_opacity_near']:.3f} / elsewhere {r['edge_opacity_far']:.3f}"
            if r["edge_opacity_near_masked"] is not None:
                gap += f" (masked {r['edge_opacity_near_masked']:.3f} / {r['edge_opacity_far_masked']:.3f})"
        print(f"{r['mesh']} seed {r['capture_seed']} {r['arc_deg']:g}° weight "
              f"{_label(r['variant'], r['seen_ground_weight'])}: "
              f"{r['object_psnr']:.2f} dB{gap}, {100 * r['outside']:.2f}% outside ({r['fits']} "
              f"fit{'s' if r['fits'] > 1 else ''})")
    for w, t in report["totals"].items():
        clean = f"; on white, of {t['clean_captures']}: within the gap {t['within_clean_gap']}, both " \
            f"{t['both_clean']}" if t["clean_captures"] else ""
        print(f"weight {w}: within the gap {t['within_gap']} of {t['captures']}, floaters {t['within_outside']}, "
              f"both {t['both']}{clean}")
    print(f"wrote {out / args.name}.json, .csv and .png")
    return 0
