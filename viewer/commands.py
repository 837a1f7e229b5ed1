"""`snapshot3d decode PHOTO -o OUT`: views, turntable, contact sheet, report (and a mesh); no torch.

Everything is written into a hidden sibling folder first and moved into place at the end
(`snapshot3d.outputs`), so that an interrupted or failed decode never leaves a half-written OUT."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from snapshot3d.errors import UserError
from snapshot3d.images import contact_sheet, write_gif, write_png, write_views
from snapshot3d.outputs import staged_folder
from snapshot3d.validate import SAMPLES, VIEW_SIZE, check_views, integer

__all__ = ["decode_command", "restore_command", "write_outputs", "POOR_DB"]

POOR_DB = 22.0
"""below this expected restore_psnr, decode warns that the views will be poor"""


def write_outputs(folder: Path, views: np.ndarray, report: dict, mesh=None) -> None:
    write_views(folder / "views", views)
    write_gif(folder / "turntable.gif", views)
    write_png(folder / "contact.png", contact_sheet(views))
    if mesh is not None:
        from snapshot3d.meshing import write_mesh
        write_mesh(mesh, folder / "mesh.glb")
    (folder / "report.json").write_text(json.dumps(report, indent=2) + "\n")


def _quality_lines(q: dict, retake: list[str] | None = None) -> list[str]:
    """What decode says about the views' expected quality (one or two lines); `retake`: what the photo check
    found wrong with the photo (the report's `retake`), which a poor estimate names."""
    expected = q.get("restore_psnr_expected_db")
    if expected is None:
        why = "no calibration shipped" if q.get("pilot_psnr_db") is not None else "a snapshot file has no markers"
        return [f"quality estimate: none ({why})"]
    lines = [f"quality estimate: restore_psnr about {expected:.1f} dB (from {q['basis']}, "
             f"typical error {q['calibration']['held_out_rmse_db']:.1f} dB)"]
    if expected < POOR_DB:
        fix = "; ".join(retake) if retake else ("retake the photo with even light, in focus, square on, and print "
                                                "the sheet larger")
        lines.append(f"warning: the views will be poor (blurred or wrong shapes): {fix}; several photos of the print "
                     f"decode better together (decode P1 P2 P3)")
    return lines


def _photo_paths(args: list) -> list:
    """decode's inputs with each folder replaced by its photos (.jpg, .jpeg, .png, by name): a phone's burst
    copied to the computer as it came."""
    out = []
    for a in args:
        if Path(a).is_dir():
            found = sorted(p for p in Path(a).iterdir()
                           if p.is_file() and p.suffix.lower() in (".jpg", ".jpeg", ".png"))
            if not found:
                raise UserError(f"{a} is a folder with no .jpg or .png photo in it")
            out += [str(p) for p in found]
        else:
            out.append(a)
    return out


def decode_command(args) -> int:
    from snapshot3d.progress import progress
    from snapshot3d.scene import save_scene

    from .decode import decode_photo
    from .mesh import decoded_mesh
    from .render import RenderConfig

    check_views(args.views, args.size, (16, VIEW_SIZE[1]))
    integer(args.samples, "--samples", *SAMPLES)
    photos = _photo_paths([args.photo] if isinstance(args.photo, (str, Path)) else list(args.photo))
    with progress(args.views, "decode", unit="view") as bar:
        dec = decode_photo(photos if len(photos) > 1 else photos[0], args.views, args.size,
                           RenderConfig(samples=args.samples), on_view=lambda i: bar.update(1))
    with staged_folder(args.output) as tmp:
        mesh = decoded_mesh(dec.baked, dec.scene.box) if args.mesh else None
        write_outputs(tmp, dec.views, dec.report, mesh)
        save_scene(dec.scene, tmp / "scene.s3d")
    r = dec.report
    print(f"decoded {', '.join(map(str, photos))}: {len(dec.views)} views of {args.size}x{args.size} in "
          f"{r['decode_ms']:.0f} ms "
          f"(scan {r['timings_ms']['scan']:.0f}, restore {r['timings_ms']['restore']:.0f}, render "
          f"{r['timings_ms']['render']:.0f}); wrote {Path(args.output)}/")
    for p in r.get("photos") or []:
        print(f"  {p['photo']}: weight {p['weight']:.2f} " + (
            f"(its pilots: gain {p['pilot_gain']:.3f}, noise {p['pilot_noise']:.3g})" if p["pilot_noise"] is not None
            else "(its pilots read no signal)"))
    for line in _quality_lines(r["quality_estimate"], r.get("retake")):
        print(line)
    if r.get("head_codes_unread"):
        print("warning: the two small codes beside the sheet's QR code (the scene's own decoder head) could not be "
              "read: the views use the shared decoder's head and will be off-colour; retake the photo closer and "
              "sharper")
    if (r.get("channel") or {}).get("advice"):
        print(f"channel: {r['channel']['advice']}")
    return 0


def restore_command(args) -> int:
    """`snapshot3d restore SNAPSHOT -o scene.s3d`: the scene back from a snapshot file (no torch)."""
    import time

    from snapshot3d.progress import progress
    from snapshot3d.reports import write_json
    from snapshot3d.scanner.qr import check_meta
    from snapshot3d.scanner.snapfile import read_snapshot
    from snapshot3d.scene import quantize_planes, save_scene

    from .decode import restore_checked, scene_from_meta

    if Path(args.output).suffix.lower() != ".s3d":
        raise UserError(f"cannot write {Path(args.output).name}: a scene is written as .s3d")
    with progress(2, "restore", unit="stage") as bar:
        rgb, meta = read_snapshot(args.snapshot, args.meta)
        check_meta(meta)   # a sheet format and codec this build reads
        t0 = time.perf_counter()
        planes, info = restore_checked(rgb, meta)
        secs = time.perf_counter() - t0
        bar.update(1)
        scene = scene_from_meta(quantize_planes(planes), meta)
        scene.name = Path(args.snapshot).stem
        save_scene(scene, args.output)
        bar.update(1)
    report = {"restore_ms": secs * 1000, "planes": list(meta.planes), "codec": meta.codec, **info}
    write_json(args.report, report)
    print(f"wrote {args.output}: {meta.planes[0]}x{meta.planes[0]} planes, {meta.planes[1]} channels, codec "
          f"{meta.codec}; restore {secs * 1000:.0f} ms")
    return 0


def serve_command(args) -> int:
    """`snapshot3d serve`: the API and the page (uvicorn), until interrupted."""
    from snapshot3d.options import config_from_args

    from .serve_config import ServeConfig
    from .serve_http import run_server
    from .server import create_app

    cfg = config_from_args(ServeConfig, args).checked()
    try:
        cfg.cache_dir().mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"cannot use {cfg.cache_dir()} as the scene cache ({e.strerror}); pass --cache FOLDER") from None
    import socket
    with socket.socket() as probe:  # a port in use is a user's mistake: say so before starting
        try:
            probe.bind((cfg.host, cfg.port))
        except OSError as e:
            raise UserError(f"cannot listen on {cfg.host}:{cfg.port} ({e.strerror}); pass another --port") from None
    app = create_app(cfg)
    print(f"snapshot3d serve: open http://{cfg.host}:{cfg.port}/ (API docs at /docs); scenes in {cfg.cache_dir()}")
    run_server(app, cfg)
    return 0
