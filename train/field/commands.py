"""The torch-side commands: `fit`, `render`, `mesh`, `train decoder`, `demo`. Each takes parsed CLI
arguments, prints a short summary and returns an exit code; user mistakes raise `UserError`."""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from snapshot3d import formats
from snapshot3d.cameras import orbit_cameras as _orbit_cameras
from snapshot3d.errors import UserError
from snapshot3d.images import contact_sheet, write_gif, write_png, write_views
from snapshot3d.options import config_from_args
from snapshot3d.outputs import staged_folder
from snapshot3d.progress import progress
from snapshot3d.reports import write_json
from snapshot3d.scene import Orbit, Scene, load_scene_file, save_scene
from snapshot3d.validate import MESH_RES, SCENE_MAX_RES, VIEW_SIZE, check_views, integer

from .config import FitConfig, check_fit_config
from .curves import payload_hint

__all__ = ["Fitted", "fit_scene", "resolve_autos", "fit_command", "render_command", "mesh_command",
           "train_decoder_command", "orbit_cameras", "render_scene"]


# --refine-poses auto on poses adjusted to the photos' matches: the corrections start at half the steps at the
# earliest (refined early, on planes still blurred, they move away from the truth; 7 noisy composites x 3 fits,
# docs/capture-record.md "The late start, side by side")
ADJUSTED_POSE_START = 0.5
# --seen-ground-weight auto: this weight where the training cameras span less than SEEN_GROUND_SPAN_DEG of azimuth
# round the box (at 120 deg: floaters 7 of 7 under 2%; at 240 deg: -0.4 dB, the teapot's floaters 2.19% -> 0.96%;
# on two full turns it cost 0.4-2.6 dB and took no floaters away; docs/capture-record.md "The rays that show the ground")
SEEN_GROUND_WEIGHT = 0.3
SEEN_GROUND_SPAN_DEG = 300.0


def _bar(desc: str, total: int):
    bar = progress(total, desc)

    def update(step, psnr):
        bar.n = step
        bar.set_postfix_str(f"psnr {psnr:.2f} dB", refresh=False)
        bar.refresh()
        if step >= total:
            bar.close()
    return update


def orbit_cameras(scene: Scene, views: int, size: int):
    """c2w (views, 4, 4), intrinsics (views, 4) of the scene's orbit at `size` x `size` pixels."""
    return _orbit_cameras(scene.orbit, views, size)


def _default_orbit(posed) -> Orbit:
    """Radius so the scene box fills the orbit's field of view, aimed at the box centre."""
    centre = posed.box.mean(0)
    half_diag = float(np.linalg.norm(posed.box[1] - posed.box[0]) / 2)
    radius = half_diag / np.sin(np.deg2rad(formats.ORBIT_FOV_DEG) / 2) * 0.9
    return Orbit(radius=round(radius, 4), target=tuple(float(x) for x in centre))


def resolve_autos(cfg: FitConfig, layout: str | None, medium: str | None) -> FitConfig:
    """cfg with its --head, --refine-poses, --bundle and --object-channel `auto` made on or off for an input of
    `layout` (the loader's: nerfstudio, colmap, blender, builtin) and `medium` (print, file or None)."""
    if cfg.head == "auto":   # the QR code carries a print's head; a file's planes are large enough without one
        cfg = replace(cfg, head="on" if medium == "print" else "off")
    if cfg.refine_poses == "auto":   # poses from a solver or an app are a little off; builtin and Blender's are exact
        cfg = replace(cfg, refine_poses="on" if layout in ("nerfstudio", "colmap") else "off")
    if cfg.bundle == "auto":   # the photos' matches refine the poses first where the fit refines them
        cfg = replace(cfg, bundle="fit" if cfg.refine_poses == "on" else "off")
    if cfg.object_channel == -1:   # the object alone's last phase through a print's noise (docs/capture.md)
        cfg = replace(cfg, object_channel=cfg.qat_fraction if medium == "print" else 0.0)
    return cfg


@dataclass(frozen=True)
class Fitted:
    """What `fit_scene` returns. `renders`: the held-out views (V, H, W, 3) RGB, None with --budget auto.
    `train_c2w` (T, 4, 4): the training poses the fit ended with (adjusted and refined where it did so), for the
    benches; `throughput`: {"rays_per_s", "samples_per_s"}. Both None with --budget auto."""
    scene: Scene
    report: dict
    renders: np.ndarray | None
    train_c2w: np.ndarray | None = None
    throughput: dict | None = None


def fit_scene(spec: str, cfg: FitConfig, budget: str = "fixed", downscale: int = 1, checkpoint=None,
              size: int = 200, quiet: bool = False, device=None, medium: str | None = None, capture=None,
              channel=None) -> Fitted:
    """Load (`capture`: snapshot3d.capture.CaptureOptions, the split, box, up axis and size limit), fit (on
    `device`: a torch.device, a --device name, or None: the CPU) and evaluate. Returns a `Fitted`: the scene, its
    report and the held-out renders. The capture is loaded before torch is imported, so that a wrong path fails at
    once; one line says what was read. `channel`: the print channel's model the budget predicts with (None: the
    `moderate` one)."""
    from snapshot3d.capture import describe
    from snapshot3d.loaders import load_scene
    from snapshot3d.scene import dequantize_planes

    posed = load_scene(spec, downscale=downscale, capture=capture, size=size) if spec.startswith("builtin:") else \
        load_scene(spec, downscale=downscale, capture=capture)
    chose = None
    if cfg.background == "auto":   # a room round the object, or an object on white: read from the frames
        from snapshot3d.capture import choose_background, with_overlap_box
        mode, why = choose_background(posed)
        cfg, chose = replace(cfg, background=mode), f"{mode} ({why})"
        if mode == "outer" and (capture is None or capture.box is None):
            posed = with_overlap_box(posed)
    late_start = cfg.refine_poses == "auto"   # poses adjusted to the photos' matches are refined on from half way
    cfg = resolve_autos(cfg, posed.info.get("layout"), medium)
    read = posed.info.get("capture")
    if read and not quiet:
        print(describe(read))
    if chose and not quiet and not spec.startswith("builtin:"):
        print(f"background: {chose}")
    from ..device import resolve_device
    from .budget import fit_ladder
    from .decoder import load_decoder
    from .evaluate import evaluate_planes
    from .fit import fit
    from .head import with_head

    device = resolve_device(device) if isinstance(device, str) else device
    decoder = load_decoder(cfg.decoder).to(device or "cpu")
    t0 = time.perf_counter()
    log = (lambda *_: None) if quiet else print
    bars = None if quiet else _bar
    report = {"background_mode": chose} if chose and not spec.startswith("builtin:") else {}
    if cfg.background == "outer" and read and str(read.get("box_from", "")).startswith("auto"):
        posed, report["background"], cfg = _tightened(posed, decoder, cfg, device, quiet, late_start)
    train_c2w = throughput = None
    if budget == "auto":
        chosen, rungs = fit_ladder(posed, decoder, cfg, log=log, progress_factory=bars, device=device, medium=medium,
                                   channel=channel)
        codes, head = rungs[chosen]["codes"], rungs[chosen]["head"]
        ev = {k: rungs[chosen][k] for k in ("field_psnr", "field_ssim")}
        steps = cfg.steps
        ev["renders"] = None
        keys = ("plane_res", "plane_channels", "scene_kb", "field_psnr", "codec_psnr", "codec_psnr_curve",
                "e2e_expected", "ending", "refit", "fit_seconds")
        report["ladder"] = [{k: r[k] for k in keys if k in r} for r in rungs]
        report["medium"] = medium
    elif budget == "fixed":
        res = fit(posed, decoder, cfg, checkpoint=checkpoint, progress=bars("fit", cfg.steps) if bars else None,
                  device=device, object_bar=(lambda n: bars("object alone", n)) if bars else None)
        codes, steps, head = res.codes, cfg.steps, res.head
        ev = evaluate_planes(dequantize_planes(codes), with_head(decoder, head), posed, background=res.state.background,
                             samples=cfg.background_samples)
        throughput = {"rays_per_s": res.state.rays / max(res.seconds, 1e-9),
                      "samples_per_s": res.state.samples / max(res.seconds, 1e-9)}
        train_c2w = posed.c2w[posed.train]   # (V, 4, 4): the poses the fit ended with, for the benches
        if res.state.poses is not None:
            from .object_carve import refined_c2w
            from .pose_refine import pose_summary
            report["pose_refinement"] = pose_summary(res.state.poses.params, res.state.frame.scale)
            train_c2w = refined_c2w(train_c2w, res.state.poses.params.detach().cpu().numpy(), res.state.frame.scale)
    else:
        raise UserError(f"--budget must be 'fixed' or 'auto', not {budget!r}")
    seconds = time.perf_counter() - t0
    scene = Scene(codes=codes, box=posed.box, orbit=_default_orbit(posed), name=posed.name, decoder_version=cfg.decoder,
                  head=head,
                  meta={"source": spec, "train_views": int(len(posed.train)), "test_views": int(len(posed.test)),
                        **({"size": size} if spec.startswith("builtin:") else {"downscale": downscale}),
                        **({"medium": medium} if medium else {})})
    report = {"field_psnr": round(float(ev["field_psnr"]), 3), "field_ssim": round(float(ev["field_ssim"]), 4),
              "scene_kb": round(scene.scene_kb, 2), "fit_seconds": round(seconds, 1), "steps": steps,
              "plane_res": scene.resolution, "plane_channels": scene.channels,
              "head": "the scene's own" if scene.head else "the shared decoder's", **report}
    if read and not spec.startswith("builtin:"):   # a builtin scene's split and box are fixed by its name and size
        report["field_psnr_on"] = "training frames (--holdout 0)" if read["holdout"] == 0 else "held-out frames"
        if cfg.background == "outer":
            report["field_psnr_on"] += (", on the object's own pixels (the planes' opacity >= 0.5), the background "
                                        "model behind them")
        report["capture"] = read
    return Fitted(scene, report, ev["renders"], train_c2w, throughput)


def seen_ground_auto(cfg: FitConfig, c2w: np.ndarray, centre) -> tuple[FitConfig, float]:
    """cfg with --seen-ground-weight -1 (auto) resolved for training cameras c2w (T, 4, 4) round the box's `centre`:
    SEEN_GROUND_WEIGHT where their azimuths span less than SEEN_GROUND_SPAN_DEG, else 0; and that span in degrees."""
    from snapshot3d.cameras import azimuth_span_deg
    span = azimuth_span_deg(c2w, centre)
    if cfg.seen_ground_weight == -1:
        cfg = replace(cfg, seen_ground_weight=SEEN_GROUND_WEIGHT if span < SEEN_GROUND_SPAN_DEG else 0.0)
    return cfg, span


def _tightened(posed, decoder, cfg, device, quiet: bool, late_start: bool = False):
    """`posed` in the automatic box tightened from a short fit's density (train/field/box_tighten.py), its
    capture account updated; what the tightening found; and cfg, where the training poses were adjusted to the
    photos' matches and `late_start` (--refine-poses auto), its pose corrections starting at ADJUSTED_POSE_START
    of the steps at the earliest, and its --seen-ground-weight auto resolved (`seen_ground_auto`)."""

    from .box_tighten import object_box, tighten_box
    box, info, adjusted = tighten_box(posed, decoder, cfg, device)
    if adjusted is not None:   # the fit starts from the bundle-adjusted training poses (cfg.bundle "fit")
        c2w = posed.c2w.copy()
        c2w[posed.train] = adjusted
        posed = replace(posed, c2w=c2w)
        if late_start:   # refined early, on planes still blurred, they move away from the truth (docs/capture.md)
            cfg = replace(cfg, pose_start=max(cfg.pose_start, ADJUSTED_POSE_START))
    cfg, span = seen_ground_auto(cfg, posed.c2w[posed.train], box.mean(0))
    info.update(azimuth_span_deg=round(span, 1), seen_ground_weight=cfg.seen_ground_weight)
    read = posed.info["capture"]
    ground = f", the ground at z = {info['ground_z']:.3g}" if info["ground_z"] is not None else ""
    ground += ", sides and top cut" if info.get("sides_cut") else ""
    if cfg.seen_ground_weight > 0 and info.get("ground_pixels") is not None:
        ground += (f", the {len(info['ground_pixels'])} pixels that show the ground kept clear (weight "
                   f"{cfg.seen_ground_weight:g}; the cameras span {span:.0f} deg)")
    info_ground = {**posed.info, "ground_z": info["ground_z"], "ground_depth": info.get("ground_depth", 0.0),
                   # the pixels that show the ground (K, 3) (train frame, row, col), not reported; the plane under them
                   "ground_pixels": info.pop("ground_pixels", None), "ground_plane": info.get("ground_plane"),
                   "ground_clear": info.get("ground_clear")}
    if info["ground_z"] is not None and cfg.object_box > 0 and cfg.object_steps > 0:   # round the object's cells
        cells_over = box
        box, more, cells = object_box(replace(posed, box=box, info=info_ground), decoder, cfg, device)
        info.update(more)
        # the object's cells (G, G, G) over the box they were found in, not reported: what --seen-ground-spare spares
        info_ground.update(object_cells=cells, object_cells_box=np.asarray(cells_over, np.float32))
        info["seen_ground_spare"] = bool(cfg.seen_ground_spare and cfg.seen_ground_weight > 0 and cells.any())
        info["object_rays"] = bool(cfg.object_rays and cells.any())   # fit.new_state draws them (--object-rays)
        ground += f", then cut round the object's cells of a {more['object_box_steps']}-step fit"
    source = (f"{info['sparse_points']} sparse points of the photos ({info['object_points']} on the object)"
              if info["box_from"] == "sparse points" else f"{info['prefit_steps']} steps' density")
    if adjusted is not None:
        source += (f", at the training poses adjusted to the photos' matches (median turn "
                   f"{info['bundle']['median_turn_deg']:.2f} deg; the fit starts from them"
                   + (" and keeps them)" if cfg.refine_poses == "off" else
                      f" and refines them from {cfg.pose_start:.0%} of the steps)"))
    read.update(box=box.tolist(), box_from=read["box_from"] + f"; tightened from {source}{ground}")
    if not quiet:
        lo, hi = (", ".join(f"{float(x):.3g}" for x in corner) for corner in box)
        print(f"box ({lo})..({hi}) (tightened from {source}{ground}, "
              f"{info.get('sparse_seconds', 0) + info['prefit_seconds'] + info.get('object_box_seconds', 0):.0f} s)")
    return replace(posed, box=box, info=info_ground), info, cfg


def fit_command(args) -> int:
    from snapshot3d.capture import CaptureOptions, parse_box, parse_up
    cfg = check_fit_config(FitConfig(**{k: getattr(args, k) for k in FitConfig.__dataclass_fields__}))
    integer(cfg.plane_res, "--plane-res", 2, SCENE_MAX_RES)   # what a scene file holds
    integer(args.size, "--size", *VIEW_SIZE)
    out = Path(args.output)
    if out.suffix != ".s3d":
        raise UserError(f"{out}: the scene file must end in .s3d")
    ckpt = out.with_name(out.name + ".ckpt") if args.budget == "fixed" else None
    if ckpt is not None and ckpt.exists() and not args.resume:
        ckpt.unlink()
    if args.medium and args.budget != "auto":
        raise UserError("--medium chooses the plane size with --budget auto; with --budget fixed give --plane-res "
                        "and --plane-channels")
    channel, channel_info = _channel_from_profile(getattr(args, "channel", None), args.medium)
    box = parse_box(getattr(args, "box", None))
    if box is None and cfg.background == "outer":   # a room around the object: a box from the cameras' overlap
        box = "auto"
    capture = CaptureOptions(holdout=getattr(args, "holdout", None), box=box,
                             up=parse_up(getattr(args, "up", None)), max_size=getattr(args, "max_size", None))
    fitted = fit_scene(args.scene, cfg, args.budget, args.downscale, ckpt, size=args.size,
                       device=args.device, medium=args.medium, capture=capture, channel=channel)
    scene, report, throughput = fitted.scene, fitted.report, fitted.throughput
    if channel_info is not None:
        report["channel"] = channel_info
    save_scene(scene, out)
    if ckpt is not None and ckpt.exists():
        ckpt.unlink()
    write_json(args.report, report)
    extra = f", {throughput['rays_per_s']:.0f} rays/s" if throughput else ""
    print(f"wrote {out}: field_psnr {report['field_psnr']:.2f} dB, field_ssim {report['field_ssim']:.3f}, "
          f"{report['scene_kb']:.1f} kB (R={scene.resolution}, C={scene.channels}"
          f"{', its own decoder head' if scene.head else ''}), {report['fit_seconds']:.0f} s{extra}")
    if args.medium is None and (hint := payload_hint(formats.DEFAULT_MEDIUM, scene)) is not None:
        print(f"{hint} (embed makes a print unless given --medium file)")   # what plain fit, then embed, would lose
    return 0


def _channel_from_profile(path, medium):
    """(ChannelModel, report entry) from `fit --channel profile.json`, printed in one line; (None, None)
    without --channel. UserError for a profile that does not load, or --channel without --medium print."""
    if path is None:
        return None, None
    if medium != "print":
        raise UserError("--channel gives the print channel the budget predicts with: use it with --budget auto "
                        "--medium print")
    from snapshot3d.scanner.calibrate import load_profile
    from snapshot3d.scanner.profile_channel import profile_channel

    from .curves import print_channel

    model, info = profile_channel(load_profile(path), print_channel())
    print(f"channel: {Path(path).name}, like {info['nearest_preset']} (severity {info['severity_position']:.2f} on "
          f"mild 0, moderate 1, severe 2): gain {model.gain:.3f}, noise {model.unit:.3g} per carrier")
    return model, {"profile": Path(path).name, **info}


def render_scene(scene: Scene, views: int, size: int, show_progress: bool = True) -> np.ndarray:
    """The scene's orbit views (views, size, size, 3) float32 RGB in [0, 1] (torch reference renderer)."""
    import torch

    from .decoder import scene_decoder
    from .render import render_views
    c2w, intr = orbit_cameras(scene, views, size)
    bar = progress(views, "render", unit="view") if show_progress else None
    out = render_views(torch.from_numpy(scene.planes()), scene_decoder(scene), scene.box, c2w, intr,
                       size, size, progress=(lambda i: bar.update(1)) if bar else None)
    if bar:
        bar.close()
    return out


def render_command(args) -> int:
    check_views(args.views, args.size)
    scene = load_scene_file(args.scene)
    views = render_scene(scene, args.views, args.size)
    out = Path(args.output)
    with staged_folder(out) as tmp:
        write_views(tmp / "views", views)
        write_gif(tmp / "turntable.gif", views)
        write_png(tmp / "contact.png", contact_sheet(views))
    print(f"wrote {len(views)} views of {args.size}x{args.size} (views/000.png ...), turntable.gif and contact.png "
          f"to {out}/")
    return 0


def mesh_command(args) -> int:
    import torch

    from snapshot3d.meshing import density_to_mesh, unit_grid, write_mesh

    from .decoder import scene_decoder
    from .field import decode, sample_planes
    from .sampler import BoxFrame

    integer(args.res, "--res", *MESH_RES)
    scene = load_scene_file(args.scene)
    if not str(args.output).lower().endswith((".glb", ".ply")):
        raise UserError(f"{args.output}: mesh output must end in .glb or .ply")
    decoder = scene_decoder(scene)
    planes = torch.from_numpy(scene.planes())
    pts = torch.from_numpy(unit_grid(args.res))
    chunks = pts.split(1 << 16)
    with torch.no_grad(), progress(len(chunks), "density grid", unit="chunk") as bar:
        sigma = []
        for p in chunks:
            sigma.append(decode(sample_planes(planes, p), decoder)[0])
            bar.update(1)
        sigma = torch.cat(sigma).numpy()
        step = BoxFrame.from_box(scene.box).step
        level = float(np.log(2.0) / step)  # one marching step is half opaque

        def colours(unit):
            return decode(sample_planes(planes, torch.from_numpy(unit)), decoder)[1].numpy()
        mesh = density_to_mesh(sigma.reshape((args.res,) * 3), level, scene.box, colours)
    write_mesh(mesh, args.output)
    print(f"wrote {args.output}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces")
    return 0


def train_decoder_command(args) -> int:
    from .config import DecoderConfig
    from .decoder import decoder_path, train_decoder
    cfg = config_from_args(DecoderConfig, args)
    out = Path(args.output) if args.output else decoder_path(cfg.version)
    ckpt = out.with_name(out.name + ".ckpt")
    from ..device import resolve_device

    summary = train_decoder(cfg, out, checkpoint=ckpt, log=lambda m: print(m, flush=True),
                            device=resolve_device(args.device))
    print(json.dumps(summary, indent=2))
    return 0
