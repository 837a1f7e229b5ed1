"""`snapshot3d embed`, `snapshot3d train codec` and `snapshot3d train print-codec`: files, checks and
reports. (`restore` is torch-free and lives in `viewer.commands`.)"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from snapshot3d import codec_layout, formats, print_layout
from snapshot3d.errors import UserError
from snapshot3d.metrics import psnr, ssim
from snapshot3d.options import config_from_args
from snapshot3d.reports import write_json
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.pixelmeta import mark
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import Scene, load_scene_file

__all__ = ["embed_command", "train_codec_command", "train_print_codec_command", "check_planes_for", "snapshot_for",
           "marked_host", "strength_for", "STRENGTHS", "HOST_PSNRS"]

STRENGTHS = (0.05, 10.0)
"""the embedding strengths `embed --strength` takes, and `--host-psnr` chooses among"""
HOST_PSNRS = (20.0, 60.0)
"""the host fidelities, in dB, `embed --host-psnr` takes"""


def check_planes_for(medium: str, scene: Scene) -> None:
    """UserError unless the medium's codec carries the scene's planes."""
    try:
        (codec_layout.check_plane_shape if medium == "file" else print_layout.check_print_planes)(
            scene.channels, scene.resolution)
    except ValueError as e:
        raise UserError(f"{e} (medium {medium})") from None


def marked_host(host: np.ndarray, scene: Scene, strength: float = 1.0) -> np.ndarray:
    """A file snapshot's host: `host` ((380, 380, 3) float RGB in [0, 1]) marked with the scene's metadata
    (`scanner.pixelmeta`, 8-bit), float32 in [0, 1]."""
    meta = scene_meta(scene, formats.FILE_CODEC, strength)
    return mark(np.clip(np.asarray(host) * 255 + 0.5, 0, 255).astype(np.uint8), meta).astype(np.float32) / 255.0


def snapshot_for(medium: str, host: np.ndarray, scene: Scene, strength: float = 1.0, refine: int = 0,
                 show_progress: bool = False) -> np.ndarray:
    """The snapshot (380, 380, 3) uint8 RGB of `scene` in `host` ((380, 380, 3) float RGB in [0, 1]) for a
    medium: `print` (the designed carriers, at the print host fidelity less 20 log10(strength) dB) or `file`
    (the invertible network, refined `refine` steps). A `file` snapshot's host is first marked with its
    metadata (`scanner.pixelmeta`), so that a shared copy stripped of its text still restores; a `print`
    snapshot's metadata travels in the sheet's QR code (and the file's text)."""
    if medium == "print":
        return print_layout.embed(host, scene.planes(), print_layout.HOST_PSNR - 20 * np.log10(strength))
    host = marked_host(host, scene, strength)
    from .hinet import load_codec
    from .refine import snapshot_of
    return snapshot_of(load_codec()[0], host, scene.planes(), refine, strength, show_progress=show_progress)


def _floor_3(x: float) -> float:
    """`x` > 0 rounded down to three significant digits (a strength the metadata's text carries exactly)."""
    e = math.floor(math.log10(x)) - 2
    return float(f"{math.floor(x / 10 ** e + 1e-9) * 10 ** e:.3g}")


def strength_for(medium: str, host: np.ndarray, scene: Scene, host_psnr: float, tol_db: float = 0.05,
                 iters: int = 8) -> float:
    """The embedding strength, in [0.05, 10] and three significant digits, at which the snapshot of `scene` in
    `host` ((380, 380, 3) float RGB in [0, 1]) keeps `host_psnr` dB of its host: `print`, exactly (its carriers
    are scaled to a host fidelity); `file`, the largest at which the network's snapshot (marked; the
    refinement holds its host fidelity) keeps it to within `tol_db` over, found by regula falsi (Illinois)
    on the host PSNR against log strength. UserError when no strength keeps it."""
    if medium == "print":
        return _floor_3(min(max(10 ** ((print_layout.HOST_PSNR - host_psnr) / 20), STRENGTHS[0]), STRENGTHS[1]))
    from .hinet import embed_planes, load_codec

    net, host8 = load_codec()[0], np.clip(np.asarray(host) * 255 + 0.5, 0, 255).astype(np.uint8)

    def over(x: float) -> float:   # dB kept over the target at strength exp(x); falls as x grows
        s = _floor_3(math.exp(x))
        return psnr(embed_planes(net, marked_host(host, scene, s), scene.planes(), s) / 255.0, host8 / 255.0) - host_psnr

    x_min, x_max = math.log(STRENGTHS[0]), math.log(STRENGTHS[1])
    hi, f_hi = 0.0, over(0.0)                   # strength 1, then halve or double it to bracket the target
    lo, f_lo = hi, f_hi
    while f_lo < 0 and lo > x_min:
        hi, f_hi = lo, f_lo
        lo = max(lo - math.log(2), x_min)
        f_lo = over(lo)
    if f_lo < 0:
        raise UserError(f"the {medium} codec keeps at most {host_psnr + f_lo:.1f} dB of this host (at --strength "
                        f"{STRENGTHS[0]:g}), not {host_psnr:g}")
    while f_hi >= 0 and hi < x_max:
        lo, f_lo = hi, f_hi
        hi = min(hi + math.log(2), x_max)
        f_hi = over(hi)
    if f_hi >= 0:
        return STRENGTHS[1]
    side = 0
    for _ in range(iters):
        if f_lo < tol_db:
            break
        x = hi - f_hi * (hi - lo) / (f_hi - f_lo)
        f = over(x)
        if f >= 0:
            lo, f_lo, f_hi = x, f, f_hi / 2 if side == -1 else f_hi
            side = -1
        else:
            hi, f_hi, f_lo = x, f, f_lo / 2 if side == 1 else f_lo
            side = 1
    return _floor_3(math.exp(lo))


def embed_command(args) -> int:
    from snapshot3d.scanner.snapfile import write_snapshot

    if args.medium not in formats.MEDIA:
        raise UserError(f"--medium must be one of {', '.join(formats.MEDIA)}, not {args.medium!r}")
    if args.strength is not None and args.host_psnr is not None:
        raise UserError("give --strength or --host-psnr, not both")
    if args.strength is not None and not STRENGTHS[0] <= args.strength <= STRENGTHS[1]:
        raise UserError("--strength must be in [{:g}, {:g}]".format(*STRENGTHS))
    if args.host_psnr is not None and not HOST_PSNRS[0] <= args.host_psnr <= HOST_PSNRS[1]:
        raise UserError("--host-psnr must be in [{:g}, {:g}] dB".format(*HOST_PSNRS))
    if not 0 <= args.refine <= 5000:
        raise UserError("--refine must be in [0, 5000] steps")
    if Path(args.output).suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise UserError(f"cannot write {Path(args.output).name}: a snapshot is written as .png (or .jpg)")
    scene = load_scene_file(args.scene)
    check_planes_for(args.medium, scene)
    host = load_host(args.host)
    t0 = time.perf_counter()
    strength = (strength_for(args.medium, host, scene, args.host_psnr) if args.host_psnr is not None
                else 1.0 if args.strength is None else args.strength)
    snap = snapshot_for(args.medium, host, scene, strength, args.refine, show_progress=True)
    secs = time.perf_counter() - t0
    codec = formats.MEDIUM_CODEC[args.medium]
    write_snapshot(args.output, snap, scene_meta(scene, codec, strength), jpeg_quality=args.jpeg_quality,
                   scale=formats.FILE_SCALE if args.medium == "file" else 1)
    host8 = (host * 255 + 0.5).astype(np.uint8)
    report = {"host_psnr": psnr(snap / 255.0, host8 / 255.0), "host_ssim": ssim(snap / 255.0, host8 / 255.0),
              "scene_kb": scene.scene_kb, "strength": strength, "medium": args.medium, "codec": codec,
              "refine_steps": args.refine if args.medium == "file" else 0, "embed_ms": secs * 1000}
    write_json(args.report, report)
    print(f"wrote {args.output}: {args.medium} medium (codec {codec}), host_psnr {report['host_psnr']:.2f} dB, "
          f"host_ssim {report['host_ssim']:.4f}, strength {strength:g}, {scene.scene_kb:.1f} kB of planes hidden, "
          f"{secs:.1f} s")
    return 0


def _finish_training(out: Path, summary: dict, t0: float) -> None:
    summary.update(seconds=round(time.time() - t0, 1), command="snapshot3d " + " ".join(sys.argv[1:]))
    out.with_suffix(".json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB) and {out.with_suffix('.json').name}")


def train_codec_command(args) -> int:
    from ..device import resolve_device
    from .config import CodecConfig
    from .data import load_codec_data
    from .hinet import codec_path
    from .training import train_codec

    cfg = config_from_args(CodecConfig, args)
    out = Path(args.output) if args.output else codec_path()
    try:
        data = load_codec_data(Path(args.scenes_dir), set(cfg.holdout_scenes.split(",")),
                               set(cfg.holdout_hosts.split(",")))
    except ValueError as e:
        raise UserError(f"{e}; fit training scenes there first (see the README's codec section)") from None
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    summary = train_codec(cfg, data, out, checkpoint=out.with_name(out.name + ".ckpt"),
                          log=lambda m: print(m, flush=True), device=resolve_device(args.device))
    _finish_training(out, summary, t0)
    return 0


def train_print_codec_command(args) -> int:
    from ..device import resolve_device
    from .print_data import CaptureConfig, load_captures, make_captures
    from .print_train import PrintCodecConfig, front_end_path, train_print_codec

    cfg = config_from_args(PrintCodecConfig, args)
    if cfg.captures < 40 or cfg.steps < 1 or cfg.batch < 1:
        raise UserError("--captures must be >= 40, --steps and --batch >= 1")
    out = Path(args.output) if args.output else front_end_path()
    out.parent.mkdir(parents=True, exist_ok=True)
    log = lambda m: print(m, flush=True)  # noqa: E731
    t0 = time.time()
    files = make_captures(Path(args.data), CaptureConfig(count=cfg.captures, seed=cfg.seed), args.workers, log)
    caps, pays, infos = load_captures(files)
    summary = train_print_codec(cfg, caps, pays, out, checkpoint=out.with_name(out.name + ".ckpt"), log=log,
                                device=resolve_device(args.device))
    summary["captures"] = {"count": len(infos), "severities": {s: sum(i["severity"] == s for i in infos)
                                                              for s in sorted({i["severity"] for i in infos})},
                           "hosts": len({i["host"] for i in infos}), "data": str(args.data)}
    _finish_training(out, summary, t0)
    return 0
