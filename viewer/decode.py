"""Photo -> turnable scene, without torch: scan (OpenCV) -> restore (ONNX) -> render (numpy + ONNX). A
snapshot file (or a copy of one that sharing re-encoded, resized or stripped of its text) skips the scan.

`decode_photo` returns the views (N, size, size, 3) float32 RGB in [0, 1], the restored scene and a
report with `detected`, `confidence`, `timings_ms` per stage, `decode_ms` (photo file to all views in
memory), a quality estimate that needs no ground truth (`viewer.quality`: the sheet's markers as a
pilot signal, and the `restore_psnr` they predict) and the channel the print codec's pilots measured
(`viewer.channel`: gain, noise, SNR, the nearest preset and advice; null values with a reason for a file codec)."""
from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from snapshot3d import formats, validate
from snapshot3d.cameras import orbit_cameras
from snapshot3d.codecs.media import CODEC_MEDIUM
from snapshot3d.errors import UserError
from snapshot3d.scene import Orbit, Scene, quantize_planes

from .bake import Baked, bake_field
from .channel import channel_report, px_per_pixel
from .march import Frame
from .media import restore_planes
from .quality import quality_estimate
from .quality_views import error_spectrum, views_psnr_expected
from .render import RenderConfig, pad_planes, render_views
from .runtime import scene_models

__all__ = ["Decoded", "DecodedScene", "decode_scene", "decode_photo", "scene_from_meta", "read_input",
           "read_photos", "restore_checked"]


@dataclass
class Decoded:
    views: np.ndarray
    scene: Scene
    report: dict
    baked: Baked


def scene_from_meta(codes: np.ndarray, meta) -> Scene:
    box = np.asarray(meta.box, np.float32).reshape(2, 3)
    target = tuple(meta.target) if meta.target else tuple(float(v) for v in box.mean(0))
    if meta.orbit:
        r, el, fov = meta.orbit
    else:
        r, el, fov = float(np.linalg.norm(box[1] - box[0])), formats.ORBIT_ELEVATION_DEG, formats.ORBIT_FOV_DEG
    return Scene(codes=codes, box=box, orbit=Orbit(r, el, fov, target), name="decoded",
                 decoder_version=meta.decoder_version, head=meta.head)


def _meta(qr: dict | None):
    from snapshot3d.scanner.qr import SheetMeta

    if qr is None:
        raise UserError("found the sheet but could not read its QR code (it holds the scene box and plane size); "
                        "retake the photo closer and sharper")
    names = {f.name for f in fields(SheetMeta)}   # not the scan's notes ("head_codes")
    return _checked(SheetMeta(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in qr.items() if k in names}))


def _checked(meta):
    from snapshot3d.scanner.qr import check_meta

    check_meta(meta)
    if meta.planes is None or meta.box is None:
        raise UserError("the snapshot's metadata lacks the plane size or the scene box (a sheet made without a "
                        "scene)")
    return meta


def _layout_refused(meta, e: ValueError) -> UserError:
    """The one-line error of a plane size or codec that the codec's layout refuses."""
    return UserError(f"codec {meta.codec} cannot restore planes of {meta.planes[0]}x{meta.planes[0]}, "
                     f"{meta.planes[1]} channels: {str(e).splitlines()[0]}")


def restore_checked(snapshot: np.ndarray, meta) -> tuple[np.ndarray, dict]:
    """`media.restore_planes` of a snapshot and its checked metadata (`scanner.qr.check_meta`): planes
    (3, C, R, R) float32 and the codec's info, every number finite. A reading the codec cannot measure (the
    print codec's pilots: infinite noise, an expected error that is not a number: the snapshot does not carry
    the planes its metadata names) is a UserError, as is a layout the codec refuses."""
    try:
        planes, info = restore_planes(snapshot, meta)
    except ValueError as e:   # the codec's own layout checks
        raise _layout_refused(meta, e) from None
    bad = sorted(k for k, v in info.items() if isinstance(v, float) and not np.isfinite(v))
    if bad or not np.all(np.isfinite(planes)):
        what = ", ".join(f"{k} {info[k]}" for k in bad) or "planes not finite"
        raise UserError(f"codec {meta.codec} read no usable signal for planes of {meta.planes[0]}x{meta.planes[0]}, "
                        f"{meta.planes[1]} channels ({what}): the snapshot does not carry what its metadata names, or "
                        f"is damaged past reading")
    return planes, info


def read_input(path, need_qr: bool = True):
    """(scan result or None, snapshot (380, 380, 3) uint8 RGB, metadata, what the file was) of a photo of a
    sheet, or of a snapshot file (its text metadata or the mark in its pixels; a copy re-encoded, resized or
    cropped by sharing is realigned). `need_qr` False: a photo whose QR code was not read gives metadata None
    (another photo of the same print may have read it) instead of a UserError."""
    import cv2

    from snapshot3d.scanner.imageio_safe import read_image_bgr
    from snapshot3d.scanner.scan import scan_file
    from snapshot3d.scanner.snapfile import metadata_text, snapshot_in_image

    img = read_image_bgr(path)
    got = snapshot_in_image(Path(path).name, cv2.cvtColor(img, cv2.COLOR_BGR2RGB), metadata_text(path))
    if got is not None:
        snapshot, meta, where = got
        return None, snapshot, _checked(meta), f"snapshot file (metadata from its {where})"
    n = formats.SNAPSHOT_SIZE
    if img.shape[:2] == (n, n):
        raise UserError(f"{Path(path).name} is {n}x{n} like a snapshot file but carries no snapshot3d metadata (no "
                        f"text chunk, no mark readable in its pixels): not a snapshot, or damaged past reading")
    res = scan_file(path, img)
    return res, res.snapshot, _meta(res.qr) if need_qr or res.qr is not None else None, "photo of a sheet"


def read_photos(paths) -> tuple:
    """`read_input` of several photos of one printed sheet (2 to `burst.MAX_PHOTOS`), combined into one capture
    (`viewer.burst`): each is scanned and its pilots read alone, then the rectified captures are averaged with the
    weights their pilots give. Returns (the scan of the photo with the largest weight, the combined capture
    (380, 380, 3) uint8 RGB, the shared metadata, what the inputs were, one dict per photo: its name, weight,
    pilot gain and noise). A UserError, prefixed with the photo's name, for a photo that does not read; also for a
    snapshot file among them, photos of different prints, or a codec without pilots."""
    from .burst import MAX_PHOTOS, MIN_MATCH, blue_weights, combine_captures, detail_match, pilot_residuals, same_sheet

    names = [Path(p).name for p in paths]
    if not 2 <= len(paths) <= MAX_PHOTOS:
        raise UserError(f"give 1 to {MAX_PHOTOS} photos of one printed sheet, not {len(paths)}")
    _refuse_copies(paths, names)
    def scanned(path, name):
        try:
            res, snapshot, meta, _ = read_input(path, need_qr=False)
        except UserError as e:
            raise UserError(f"{name}: {e}") from None
        if res is None:
            raise UserError(f"{name} is a snapshot file: only photos of one printed sheet are combined; decode it "
                            f"alone")
        return res, snapshot, meta
    with ThreadPoolExecutor(min(len(paths), os.cpu_count() or 1)) as pool:   # OpenCV and numpy release the GIL
        got = list(pool.map(scanned, paths, names))   # the first photo in order that fails raises
    read = [i for i, g in enumerate(got) if g[2] is not None]   # the photos whose QR code was read
    if not read:
        _meta(None)   # the one-line error of a photo whose QR code cannot be read
    meta = same_sheet([names[i] for i in read], [got[i][2] for i in read])
    first = read[0]
    for i, ((_, snapshot, _), name) in enumerate(zip(got, names)):
        r = detail_match(got[first][1], snapshot) if i != first else 1.0
        if r < MIN_MATCH:
            raise UserError(f"{name} shows another print than {names[first]} (the same scene in another picture: "
                            f"their details match at r = {r:.2f}, photos of one print at 0.5 or more): give photos of "
                            f"one printed sheet")
    if CODEC_MEDIUM[meta.codec] != "print":
        raise UserError(f"the photos' sheet carries codec {meta.codec} (the {CODEC_MEDIUM[meta.codec]} medium), which "
                        f"has no pilots to weigh photos by: decode one photo")
    reads = []
    for _, snapshot, _ in got:
        try:
            reads.append(pilot_residuals(snapshot, *meta.planes, meta.codec))
        except ValueError as e:   # the codec's own layout checks
            raise _layout_refused(meta, e) from None
    try:   # a photo whose pilots read nothing weighs 0
        w = blue_weights([g for g, _ in reads], [r for _, r in reads])
    except ValueError:
        raise UserError(f"codec {meta.codec} read no signal in the pilots of any of the {len(paths)} photos (they do "
                        f"not show the sheet's snapshot, or are damaged past reading)") from None
    combined = combine_captures(np.stack([g[1] for g in got]), w)
    photos = [{"photo": n, "weight": round(float(wi), 4), "pilot_gain": round(g, 4) if np.isfinite(g) else None,
               "pilot_noise": float(f"{np.mean(r * r):.4g}") if np.all(np.isfinite(r)) else None,
               "qr_read": gi[0].qr is not None, "head_read": _head_read(gi[0].qr), "photo_check": gi[0].photo}
              for n, wi, (g, r), gi in zip(names, w, reads, got)]
    return got[int(np.argmax(w))][0], combined, meta, f"{len(paths)} photos of a sheet, combined", photos


def _refuse_copies(paths, names: list[str]) -> None:
    """A UserError naming the first photo given twice (the same bytes, under its own or another name): a copy adds
    nothing to the combination. A file that cannot be read is left to the scan's own error."""
    import hashlib

    seen = {}
    for path, name in zip(paths, names):
        try:
            digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
        except OSError:
            continue
        if digest in seen:
            same = "is given twice" if seen[digest] == name else f"is a copy of {seen[digest]}"
            raise UserError(f"{name} {same}: give different photos of one printed sheet (a copy adds nothing)")
        seen[digest] = name


def _head_read(qr: dict | None) -> bool | None:
    """Whether a photo's scan read the scene's own head (None: its QR code was not read, or names no head)."""
    if qr is None or (qr.get("head") is None and qr.get("head_codes") != "unread"):
        return None
    return qr.get("head") is not None


def _inputs(path) -> tuple:
    """`read_input` of one path, `read_photos` of a list or tuple of more: (scan, snapshot, meta, source,
    photos or None)."""
    paths = [path] if isinstance(path, (str, Path)) else list(path)
    if len(paths) == 1:
        return (*read_input(paths[0]), None)
    return read_photos(paths)


@dataclass
class DecodedScene:
    """A photo or snapshot file turned into a scene and its baked grid, before any view is rendered
    (what `snapshot3d serve` keeps; `decode_photo` renders the orbit from it)."""
    scene: Scene
    baked: Baked
    planes: np.ndarray  # (3, C, R, R) float32 in [-1, 1], as restored (before quantisation)
    report: dict
    snapshot: np.ndarray  # (380, 380, 3) uint8 RGB: the capture the restore read (rectified and colour-corrected)
    codec_info: dict = field(default_factory=dict)  # what the codec said of its reading (`media.restore_planes`)


def _views_psnr(scene: Scene, planes: np.ndarray, codec: str, info: dict) -> float | None:
    """The print codec's `quality_views.views_psnr_expected` of restored planes (None for the file codec)."""
    if CODEC_MEDIUM[codec] != "print":
        return None
    err = error_spectrum(codec, planes.shape[2], planes.shape[1], info["pilot_gain"], info["pilot_noise"],
                         info["plane_rmse_expected"])
    return views_psnr_expected(scene_models(scene), planes, scene.box, scene.orbit, err)


def _with_estimate(ds: "DecodedScene", timings: dict, channel, estimate) -> dict:
    """ds.report with the channel block (`channel`: a callable -> it, `_scene`'s) and the quality estimate
    with its views term (`estimate`: `_scene`'s callable views_psnr -> the estimate), built once; its time as
    timings["quality"]."""
    report = dict(ds.report, channel=channel())
    t0 = time.perf_counter()
    views = _views_psnr(ds.scene, ds.planes, report["codec"], ds.codec_info)
    report["quality_estimate"] = estimate(views)
    report["timings_ms"] = dict(timings, quality=round((time.perf_counter() - t0) * 1e3, 1))
    return validate.finite_tree(report, "report")


def decode_scene(path, cfg: RenderConfig = RenderConfig(), estimate: bool = True) -> DecodedScene:
    """Scan (or read the snapshot file), restore and bake; the report has the timings of these stages. `path`:
    one photo or snapshot file, or a list of photos of one printed sheet (`read_photos`; their reading alone
    counts in the scan's time).
    `estimate`: also render the quality estimate's few small views (`viewer.quality_views`; `decode_photo`
    does that after the views, so that they come first)."""
    ds, channel, quality = _scene(path, cfg)
    ds.report = _with_estimate(ds, ds.report["timings_ms"], channel, quality) if estimate else \
        validate.finite_tree(dict(ds.report, channel=channel(), quality_estimate=quality(None)), "report")
    return ds


def _scene(path, cfg: RenderConfig):
    """`decode_scene` without the channel block or the quality estimate (None in the report); a callable ->
    the channel block, for after the first view; and a callable views_psnr (None: no views term) -> the
    quality estimate, so that it is built once, with or without its views term."""
    t0 = time.perf_counter()
    res, snapshot, meta, source, photos = _inputs(path)
    t1 = time.perf_counter()
    planes, codec_info = restore_checked(snapshot, meta)
    t2 = time.perf_counter()
    scene = scene_from_meta(quantize_planes(planes), meta)
    baked = bake_field(scene_models(scene), pad_planes(planes), Frame.from_box(scene.box),
                       cfg.bake)
    t3 = time.perf_counter()
    ms = lambda a, b: round((b - a) * 1e3, 1)  # noqa: E731
    pilot = None if res is None or res.pilot_psnr is None else round(float(res.pilot_psnr), 2)  # as the report shows
    report = {
        "source": source,
        "detected": True, "confidence": None if res is None else round(float(res.confidence), 3),
        "timings_ms": {"scan": ms(t0, t1), "restore": ms(t1, t2), "bake": ms(t2, t3)},
        "codec": meta.codec, "medium": CODEC_MEDIUM[meta.codec],
        "quality_estimate": None,   # `estimate` below, after the views
        "channel": None,   # `channel` below, after the views
        "planes": list(meta.planes), "decoder": scene.decoder_version, "own_head": scene.head is not None,
        "head_codes_unread": meta.head is None and (any(p["head_read"] is False for p in photos) if photos else
                                                    bool(res is not None and res.qr and
                                                         res.qr.get("head_codes") == "unread")),
        "render": cfg.__dict__,
        "field_evaluations": baked.evaluated,
        "scan": None if res is None else {k: v for k, v in res.report().items()
                                          if k in ("corners", "reprojection_px", "qr", "photo")},
    }
    # what to change when the photo is taken again (the photo check's measures over their limits; for several
    # photos, the one with the largest weight's)
    from snapshot3d.scanner.photo_check import PhotoCheck
    report["retake"] = PhotoCheck(**res.photo).causes() if res is not None and res.photo else []
    if photos is not None:   # several photos: the scan above is the one with the largest weight
        report["photos"] = photos
    px = None if res is None else px_per_pixel(res.corners)
    blur = None if res is None or not res.photo else res.photo["blur_px"]
    channel = lambda: channel_report(meta.codec, snapshot, meta.planes, codec_info, px, blur)  # noqa: E731

    def estimate(views_psnr: float | None) -> dict:
        return quality_estimate(meta.codec, pilot, codec_info.get("plane_rmse_expected"), views_psnr)
    return (DecodedScene(scene, baked, planes, validate.finite_tree(report, "report"), snapshot, codec_info),
            channel, estimate)


def decode_photo(path, views: int = formats.ORBIT_VIEWS, size: int = formats.ORBIT_SIZE,
                 cfg: RenderConfig = RenderConfig(), on_view=None) -> Decoded:
    """The orbit's `views` views (size x size) of a photo or snapshot file, or of several photos of one sheet
    (a list: `read_photos`); `on_view(i)` as each is done. Only
    what the views need comes before them: the channel block and the estimate's views term follow them
    (`timings_ms["first_view"]` and `decode_ms` count from the call, neither includes those two)."""
    t0 = time.perf_counter()
    ds, channel, quality = _scene(path, cfg)   # the channel block and the estimate come after the views
    t3 = time.perf_counter()
    c2w, intr = orbit_cameras(ds.scene.orbit, views, size)
    first = []

    def _tick(i):  # may run on worker threads: list.append is atomic
        if not first:
            first.append(time.perf_counter())
        if on_view is not None:
            on_view(i)
    out = render_views(scene_models(ds.scene), ds.planes, ds.scene.box, c2w, intr, size, size, cfg, baked=ds.baked,
                       on_view=_tick)
    t4 = time.perf_counter()
    ms = lambda a, b: round((b - a) * 1e3, 1)  # noqa: E731
    report = _with_estimate(ds, dict(ds.report["timings_ms"], render=ms(t3, t4),
                                     first_view=ms(t0, first[0]) if first else None), channel, quality)
    report.update(views=views, size=size, decode_ms=ms(t0, t4))   # photo to views; the estimate comes after
    return Decoded(out, ds.scene, report, ds.baked)
