"""`snapshot3d bench print-ablation`: where a physical severity's error comes from (issue 37).

Each photo is simulated again with one knob of the severity's preset set to its ideal (`dataclasses.replace`; the
random draws stay in step, so the photo is the same but for that knob, except where a changed pose takes the sheet's
placement more or fewer tries: `_pairs`) and read as `decode` reads one photo.
Variants (`VARIANTS`): the light (even, or without only its gradient, shadow or glare), the halftone, the paper's
fibre, the printer's tone and gamut (a linear printer), the tilt and lens, the blur, the sensor noise, the JPEG,
the white balance; the print alone (every camera effect ideal) and the camera alone (an ideal print);
`oracle-flat-field` divides the preset's own capture by the light the scanner left on it, measured on a photo of
a blank sheet under the same pose and light (what a perfect flat field could give).
Rows (print_ablation.csv): per photo and variant, `restore_psnr` (orbit views against the original planes'),
`e2e_psnr` (held-out ground-truth views), the planes' RMS error, and what decode's photo check measured
(`check_*`: tilt, blur, glare; `scanner.photo_check`) beside the simulator's own draws (`true_*`).
print_ablation.json: medians per variant and their differences from the preset's, the paired median gains over the
preset (wins of the pairs, the photos whose variant kept the preset's draws after the pose), and `photo_check`: the gain of removing glare, the tilt or
the blur on the photos the check would name it for, against the others; print_ablation.png: the paired gains."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import cv2
import numpy as np

from snapshot3d.errors import UserError
from snapshot3d.scanner.photo_check import BLUR_MAX, GLARE_MAX, TILT_MAX_DEG

from .common import median, pyplot, write_report

__all__ = ["bench_print_ablation_command", "VARIANTS", "variant_preset", "flat_field_fix"]

_EVEN = {"gradient": (0.0, 0.0), "shadow": (0.0, 0.0), "glare": (0.0, 0.0)}
_CAMERA = {**_EVEN, "tilt_deg": (0.0, 0.0), "k1": (0.0, 0.0), "defocus_px": (0.0, 0.0), "motion_px": (0.0, 0.0),
           "noise_shot": (0.0, 0.0), "noise_read": (0.0, 0.0), "jpeg_quality": (100, 100), "white_balance": 0.0}
_PRINTER = {"tone_gamma": 1.0, "gamut": 1.0, "ink_black": 0.0, "paper_white": (1.0, 1.0, 1.0)}
VARIANTS = {
    "preset": {},
    "even-light": _EVEN,
    "no-gradient": {"gradient": (0.0, 0.0)},
    "no-shadow": {"shadow": (0.0, 0.0)},
    "no-glare": {"glare": (0.0, 0.0)},
    "no-halftone": {"halftone": False},
    "no-paper-texture": {"paper_texture": 0.0},
    "linear-printer": _PRINTER,
    "no-tilt-or-lens": {"tilt_deg": (0.0, 0.0), "k1": (0.0, 0.0)},
    "no-blur": {"defocus_px": (0.0, 0.0), "motion_px": (0.0, 0.0)},
    "no-sensor-noise": {"noise_shot": (0.0, 0.0), "noise_read": (0.0, 0.0)},
    "jpeg-100": {"jpeg_quality": (100, 100)},
    "no-white-balance": {"white_balance": 0.0},
    "print-alone": _CAMERA,
    "camera-alone": {**_PRINTER, "halftone": False, "paper_texture": 0.0},
}
"""variant -> the preset's knobs set to their ideal (every knob keeps its random draw: uniform(0, 0) draws too)"""
_BLANK = {"noise_shot": (0.0, 0.0), "noise_read": (0.0, 0.0), "jpeg_quality": (100, 100), "halftone": False,
          "paper_texture": 0.0}
"""the blank sheet's photo for the oracle flat field: the same pose, light and blur, no noise of its own"""
_BLANK_GREY = 190
_LIGHT_BLUR = 6.0


def variant_preset(severity: str, variant: str):
    """The `scanner.presets.Preset` of `severity` with `VARIANTS[variant]`'s knobs set."""
    from snapshot3d.scanner.presets import get_preset
    return dataclasses.replace(get_preset(severity), **VARIANTS[variant])


def flat_field_fix(capture: np.ndarray, blank: np.ndarray) -> np.ndarray:
    """A rectified capture (380, 380, 3) uint8 RGB divided, in linear light, by the light the scanner left on the
    rectified capture of a blank sheet `blank` (same layout), smoothed and relative to its median: uint8 RGB."""
    from snapshot3d.scanner.printing import linear_to_srgb_u8, srgb_to_linear
    light = cv2.GaussianBlur(srgb_to_linear(blank), (0, 0), _LIGHT_BLUR)
    light = light / np.maximum(np.median(light.reshape(-1, 3), axis=0), 1e-6)
    return linear_to_srgb_u8(srgb_to_linear(capture) / np.maximum(light, 1e-3))


def _scan(data: bytes):
    """The scan (`ScanResult`) of an encoded photo, or None where the scanner refuses it."""
    from snapshot3d.scanner.scan import scan_image
    try:
        return scan_image(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))
    except UserError:
        return None


def _photo_rows(sheet, blank, severity: str, seed: int, score) -> list[dict]:
    """One photo (`seed`) under every variant and the oracle flat field of the preset's capture, each scored by
    `score` (a rectified capture -> a dict of measures); a variant whose photo the scanner cannot read has no row."""
    from snapshot3d.scanner.simulate import simulate
    rows, pseed = [], 500 + seed
    for name in VARIANTS:
        data, _, truth = simulate(sheet, variant_preset(severity, name), seed, print_seed=pseed)
        scan = _scan(data)
        if scan is None:
            continue
        check = {f"check_{k}": v for k, v in scan.photo.items()}   # what decode measures of the photo
        drawn = truth["sampled"]
        check.update(true_tilt_deg=truth["pose"]["tilt_deg"], true_glare=drawn["glare"],
                     true_defocus_px=drawn["defocus_px"], true_motion_px=drawn["motion_px"],
                     true_albedo=drawn["background_albedo"])
        rows.append(dict(variant=name, seed=seed, **check, **score(scan.snapshot)))
        if name == "preset":
            ref = _scan(simulate(blank, dataclasses.replace(variant_preset(severity, name), **_BLANK), seed,
                                 print_seed=pseed)[0])
            if ref is not None:
                rows.append(dict(variant="oracle-flat-field", seed=seed, **check,
                                 **score(flat_field_fix(scan.snapshot, ref.snapshot))))
    return rows


_NAMED = {"no-glare": ("check_glare_share", GLARE_MAX), "no-tilt-or-lens": ("check_tilt_deg", TILT_MAX_DEG),
          "no-blur": ("check_blur_px", BLUR_MAX)}
"""variant -> the photo check's measure and the limit over which a poor decode names that cause"""


def _pairs(rows: list[dict], name: str) -> list[tuple[dict, dict]]:
    """(preset's row, variant's row) of each photo whose variant kept the preset's draws after the pose: a variant
    that changes the pose (tilt, lens) can change how many draws the sheet's placement takes, and with them the
    light, blur and noise drawn after it; the background's albedo, drawn right after the pose and set by no variant,
    tells."""
    base = {(r["host"], r["seed"]): r for r in rows if r["variant"] == "preset"}
    return [(base[(r["host"], r["seed"])], r) for r in rows
            if r["variant"] == name and (r["host"], r["seed"]) in base
            and r["true_albedo"] == base[(r["host"], r["seed"])]["true_albedo"]]


def _named(rows: list[dict]) -> dict:
    """Per cause the photo check names: the paired restore_psnr gain of removing it, split by whether the preset's
    photo was over the check's limit (medians, and how many photos)."""
    out = {}
    for name, (key, limit) in _NAMED.items():
        d = {True: [], False: []}
        for b, r in _pairs(rows, name):
            if b[key] is not None:
                d[b[key] > limit].append(r["restore_psnr"] - b["restore_psnr"])
        out[name] = {"measure": key, "limit": limit, **{
            ("over" if k else "under"): {"photos": len(v), "restore_psnr_gain": float(np.median(v)) if v else None}
            for k, v in d.items()}}
    return out


def _summary(rows: list[dict]) -> dict:
    out = {}
    for name in dict.fromkeys(r["variant"] for r in rows):
        at = [r for r in rows if r["variant"] == name]
        s = {k: median(at, k) for k in ("restore_psnr", "e2e_psnr")}
        base = [r for r in rows if r["variant"] == "preset"]
        s.update({f"{k}_median_diff": s[k] - median(base, k) for k in ("restore_psnr", "e2e_psnr")})   # unpaired
        pairs = _pairs(rows, name)
        for k in ("restore_psnr", "e2e_psnr"):   # paired only where the variant kept the preset's later draws
            d = [r[k] - b[k] for b, r in pairs]
            s[f"{k}_gain"] = float(np.median(d)) if d else None
            s[f"{k}_wins"] = f"{sum(x > 0 for x in d)}/{len(d)}"
        out[name] = dict(s, photos=len(at), pairs=len(pairs))
    return out


def _chart(doc: dict, path: Path) -> None:
    plt = pyplot()
    s = {k: v for k, v in doc["summary"].items() if k != "preset"}
    names = list(s)
    y = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(7.5, 0.35 * len(names) + 1.4))
    for off, key, label in ((-0.2, "restore_psnr_gain", "restore_psnr"), (0.2, "e2e_psnr_gain", "e2e_psnr")):
        ax.barh(y + off, [s[n][key] or 0.0 for n in names], height=0.38, label=label)
    ax.set_yticks(y, names)
    ax.invert_yaxis()
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlabel(f"paired median gain over the preset (dB), {doc['severity']}")
    ax.set_title(f"{doc['scene']}: {doc['photos']} photos, one knob at its ideal", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def bench_print_ablation_command(args) -> int:
    from snapshot3d.codecs.media import MEDIA
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.presets import get_preset
    from snapshot3d.scanner.qr import scene_meta
    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.scene import load_scene_file
    from snapshot3d.validate import integer
    from snapshot3d.viewer.media import restore_planes

    from .codec_print import E2E, _snapshot, heldout_hosts
    from .common import ViewJudge

    integer(args.seeds, "--seeds", 1, 100)
    if not get_preset(args.severity).physical:
        raise UserError(f"--severity {args.severity} is not a physical severity (mild, moderate or severe)")
    t0 = time.time()
    out = Path(args.out)
    scene = load_scene_file(args.scene)
    meta = scene_meta(scene, MEDIA["print"].codec, 1.0)
    e2e, judge, truth = E2E(scene, args.views), ViewJudge(scene, args.size), scene.planes()
    rows = []
    for spec in ["builtin:" + h for h in args.hosts.split(",") if h] + heldout_hosts(args.heldout):
        host = Path(spec.split(":", 1)[-1]).stem
        snap = _snapshot("print", load_host(spec), scene)
        sheet, blank = render_sheet(snap, meta, 2), render_sheet(np.full_like(snap, _BLANK_GREY), meta, 2)

        def score(cap, host=host):
            planes, _ = restore_planes(cap, meta)
            return {"host": host, "restore_psnr": judge.planes_psnr(planes), "e2e_psnr": e2e.psnr(planes),
                    "plane_rmse": float(np.sqrt(np.mean((planes - truth) ** 2)))}
        for seed in range(args.seeds):
            rows += _photo_rows(sheet, blank, args.severity, seed, score)
            print(f"{host} seed {seed} ({time.time() - t0:.0f} s)", flush=True)
    doc = write_report(out, "print_ablation", rows, {
        "scene": Path(args.scene).stem, "severity": args.severity, "field_psnr": e2e.psnr(truth),
        "photos": len({(r["host"], r["seed"]) for r in rows if r["variant"] == "preset"}), "views": args.views,
        "summary": _summary(rows), "photo_check": _named(rows), "seconds": round(time.time() - t0, 1)})
    _chart(doc, out / "print_ablation.png")
    def gain(x):
        return "no pair" if x is None else f"{x:+.2f}"
    for name, s in doc["summary"].items():
        print(f"{name:18s} restore {s['restore_psnr']:6.2f} ({gain(s['restore_psnr_gain'])}, {s['restore_psnr_wins']})"
              f"  e2e {s['e2e_psnr']:6.2f} ({gain(s['e2e_psnr_gain'])}, {s['e2e_psnr_wins']})")
    for name, s in doc["photo_check"].items():
        print(f"{name}: photos over {s['measure']} {s['limit']}: {s['over']['photos']}, gain "
              f"{s['over']['restore_psnr_gain']}; under: {s['under']['photos']}, gain {s['under']['restore_psnr_gain']}")
    print(f"wrote {out}/print_ablation.csv, print_ablation.json, print_ablation.png ({time.time() - t0:.0f} s)")
    return 0
