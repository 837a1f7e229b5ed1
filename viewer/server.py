"""`snapshot3d serve`: the scan-and-view HTTP API and the phone page (FastAPI; torch-free like the decode
path; OpenAPI at /docs). The work is in `viewer.serving`; this module maps it onto routes, limits and
one-line JSON errors ({"error": "..."}; never a stack trace).

Limits (`ServeConfig`): upload bytes (Content-Length checked before the body is read; 413), photo pixels
(read from the header before decoding; 413), concurrent decodes (a fixed number of slots; when all are
busy, 503 with Retry-After: never an unbounded queue), a per-decode time limit (503; the late result is
dropped, and its slot stays taken until it ends, so the bound holds), scenes kept (count and bytes,
least recently used evicted), request bodies' read time (408, `viewer.serve_guard`). Busy refusals log one
line per 10 s, with their count (`serve_guard.BusyLog`); every other refusal one line each. Everything a client
sends answers 2xx, 4xx or 503; a 500 is a bug in the server (JSON too, its traceback in the log). Routes,
limits and the malformed-HTTP answers: docs/serve-api.md."""
from __future__ import annotations

import asyncio
import gzip
import json
import re
import secrets
import shutil
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from pathlib import Path

from fastapi import FastAPI, File, Query, Request, UploadFile
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from snapshot3d import __version__, formats
from snapshot3d.codecs.print_feeds import layout_npz
from snapshot3d.errors import UserError
from snapshot3d.scanner.imageio_safe import image_size

from .burst import MAX_PHOTOS
from .render import RenderConfig
from .runtime import model_path
from .serve_config import ServeConfig
from .serve_guard import ApiError, BusyLog, Guard, error_response, log_refusal, printable
from .serving import BakedCache, mesh_file, orbit_view_png, render_png, write_scene
from .store import SceneStore, StoreLimits

__all__ = ["ApiError", "create_app", "STATIC"]

STATIC = Path(__file__).resolve().parent / "static"
DECODE_PATH = "/v1/decode"
# `restore` is the file codec embed writes now; `restore-<codec>` names each file codec this build reads, so that
# a client can fetch the graph an older snapshot's metadata names (docs/onnx-contract.md section 2)
MODEL_ROUTES = ("restore", *(f"restore-{c}" for c in formats.FILE_CODECS), "restore-print", "project", "field",
                *(f"{k}-{d}" for d in formats.DECODERS for k in ("project", "field")))
RENDER_DISTANCE = (0.01, 50.0)  # /render's distance, in orbit radii


class Busy(ApiError):
    """503: every decode slot is taken (logged by `BusyLog`, not one line each)."""


class Decoder:
    """Runs decodes on `max_decodes` threads, never more at once; `submit` refuses when all are busy."""

    def __init__(self, cfg: ServeConfig, store: SceneStore, baked: BakedCache):
        self.cfg, self.store, self.baked = cfg, store, baked
        self.pool = ThreadPoolExecutor(cfg.max_decodes, thread_name_prefix="decode")
        self.slots = threading.BoundedSemaphore(cfg.max_decodes)

    def busy(self) -> Busy:
        return Busy(503, f"busy: {self.cfg.max_decodes} decodes are running; retry shortly", {"Retry-After": "2"})

    def _job(self, uploads: list[Path], dropped: threading.Event) -> tuple[str, dict]:
        tmp = self.store.staging()
        try:
            ds = write_scene(tmp, uploads if len(uploads) > 1 else uploads[0])
            if dropped.is_set():
                raise ApiError(503, "dropped after the time limit")
            sid = self.store.publish(tmp)
            self.baked.put(sid, ds.scene, ds.baked)
            return sid, json.loads((self.store.root / sid / "report.json").read_text())
        finally:
            self.store.discard(tmp)
            shutil.rmtree(uploads[0].parent, ignore_errors=True)
            self.slots.release()

    async def run(self, uploads: list[Path]) -> tuple[str, dict]:
        """Decode the uploaded files (one photo or snapshot file, or several photos of one sheet, all in one
        folder, which is removed after)."""
        if not self.slots.acquire(blocking=False):
            shutil.rmtree(uploads[0].parent, ignore_errors=True)
            raise self.busy()
        dropped = threading.Event()
        fut = self.pool.submit(self._job, uploads, dropped)
        try:
            return await asyncio.wait_for(asyncio.wrap_future(fut), self.cfg.timeout_s)
        except asyncio.TimeoutError:
            dropped.set()
            raise ApiError(503, f"the decode took longer than the time limit ({self.cfg.timeout_s:g} s); retry later",
                           {"Retry-After": "5"}) from None


def _links(sid: str) -> dict:
    base = f"/v1/scenes/{sid}"
    return {"views": [f"{base}/views/{i}.png" for i in range(formats.ORBIT_VIEWS)], "render": f"{base}/render",
            "scene": f"{base}/scene.s3d", "mesh": f"{base}/mesh.glb", "grid": f"{base}/grid",
            "capture": f"{base}/capture.png"}


def create_app(cfg: ServeConfig = ServeConfig()) -> FastAPI:
    store = SceneStore(cfg.cache_dir(), StoreLimits(cfg.max_scenes, cfg.max_cache_mb))
    baked = BakedCache(cfg.keep_baked)
    rcfg = RenderConfig(probe_div=cfg.render_probe_div, workers=1)  # one view on one thread: measured faster
    # than splitting it over threads (the work is short numpy calls), and it leaves the other cores to other requests
    decoder = Decoder(cfg, store, baked)
    uploads = Path(tempfile.mkdtemp(prefix=".uploads.", dir=store.root))
    app = FastAPI(title="snapshot3d", version=__version__, redirect_slashes=False,  # no 307 to a client's Host
                  description="Scan-and-view backend: upload a phone photo of a printed snapshot3d sheet, or a "
                              "snapshot file; get a scene id, its report and views; render any view on demand; "
                              "download the scene, the mesh or the baked grid. Errors are JSON "
                              '{"error": "<one line>"}.')
    app.state.config, app.state.store, app.state.decoder = cfg, store, decoder
    app.state.busy_log = busy_log = BusyLog()
    app.add_middleware(Guard, upload_path=DECODE_PATH, max_bytes=int(cfg.max_upload_mb * 1e6),
                       read_timeout_s=cfg.read_timeout_s, upload_timeout_s=cfg.upload_timeout_s)

    def _refuse(request, status: int, message: str, headers: dict | None = None):
        log_refusal(request.scope, status, message)
        return error_response(status, message, headers)

    @app.exception_handler(ApiError)
    async def _api_error(request, e: ApiError):
        if isinstance(e, Busy):
            busy_log.refuse(request.scope, e.message, cfg.max_decodes)
            return error_response(e.status, e.message, e.headers)
        return _refuse(request, e.status, e.message, e.headers)

    @app.exception_handler(UserError)
    async def _user_error(request, e: UserError):
        return _refuse(request, 422, str(e))

    @app.exception_handler(RequestValidationError)
    async def _invalid(request, e: RequestValidationError):
        first = e.errors()[0] if e.errors() else {}
        where = ".".join(str(p) for p in first.get("loc", ()) if p not in ("query", "path", "body"))
        return _refuse(request, 422, f"invalid {where or 'request'}: {first.get('msg', 'malformed')}")

    @app.exception_handler(StarletteHTTPException)
    async def _http(request, e: StarletteHTTPException):
        message = str(e.detail) if e.status_code != 404 else f"not found: {printable(request.url.path)}"
        return _refuse(request, e.status_code, message, getattr(e, "headers", None))

    def _folder(sid: str) -> Path:
        folder = store.folder(sid)
        if folder is None:
            raise ApiError(404, f"no scene {sid[:40]!r} (unknown, or evicted from the cache)")
        return folder

    def _read(sid: str, name: str) -> bytes:
        """A file of the scene; 404 if the scene is unknown or was evicted (even while this request ran)."""
        try:
            return (_folder(sid) / name).read_bytes()
        except FileNotFoundError:
            raise ApiError(404, f"scene {sid!r} has no {name} (evicted from the cache, or decoded by an older "
                                "version)") from None

    def _made(sid: str, make, *args):
        try:
            return make(*args)
        except FileNotFoundError:  # the scene was evicted while its view or mesh was made
            raise ApiError(404, f"no scene {sid!r} (evicted from the cache)") from None

    def _baked(sid: str):
        folder = _folder(sid)
        try:
            return (folder, *baked.get(sid, folder))
        except FileNotFoundError:
            raise ApiError(404, f"no scene {sid!r} (evicted from the cache)") from None

    @app.get("/healthz", summary="liveness and limits")
    def healthz():
        return {"ok": True, "version": __version__, "scenes": len(store.ids()), "limits": asdict(cfg)}

    @app.post(DECODE_PATH, summary="decode a phone photo of a sheet, or a snapshot file, into a scene; or several "
                                   "photos of one printed sheet, combined")
    async def decode(file: list[UploadFile] = File(..., description="JPEG or PNG: a photo of a printed sheet, or a "
                                                                    "snapshot file (its metadata in its text or "
                                                                    "pixels); repeat the field for up to "
                                                                    f"{MAX_PHOTOS} photos of one printed sheet")):
        if len(file) > MAX_PHOTOS:
            raise ApiError(422, f"{len(file)} files: give 1 to {MAX_PHOTOS} photos of one printed sheet")
        (uploads / (token := secrets.token_hex(8))).mkdir()
        paths = []
        try:
            for i, part in enumerate(file):
                name = re.sub(r"[^A-Za-z0-9._-]", "_", Path(part.filename or "").name)[-80:].lstrip(".") or "upload"
                if any(p.name == name for p in paths):
                    name = f"{i + 1}-{name}"
                path = uploads / token / name  # errors name the user's file, not a temporary one
                paths.append(path)
                with path.open("wb") as f:
                    while chunk := await part.read(1 << 20):
                        f.write(chunk)
                try:
                    w, h, _ = image_size(path, "upload")
                except UserError as e:
                    raise ApiError(413 if "pixels" in str(e) else 415, str(e)) from None
                if w * h > cfg.max_pixels_mp * 1e6:
                    raise ApiError(413, f"photo {name} of {w}x{h} pixels ({w * h / 1e6:.0f} MP) is over the "
                                        f"{cfg.max_pixels_mp:.0f} MP limit")
        except BaseException:
            shutil.rmtree(uploads / token, ignore_errors=True)
            raise
        sid, report = await decoder.run(paths)
        return {"scene_id": sid, "report": report, **_links(sid)}

    @app.get("/v1/scenes/{sid}", summary="a scene's report and links")
    def scene_info(sid: str):
        report = json.loads(_read(sid, "report.json"))
        return {"scene_id": sid, "report": report, **_links(sid)}

    @app.get("/v1/scenes/{sid}/render", summary="one view rendered on demand (PNG)",
             response_class=Response, responses={200: {"content": {"image/png": {}}}})
    def render(sid: str, azimuth: float = Query(0.0, ge=-3600, le=3600, allow_inf_nan=False,
                                                description="degrees; 0 = view 0"),
               elevation: float = Query(formats.ORBIT_ELEVATION_DEG, ge=-89.9, le=89.9, allow_inf_nan=False,
                                        description="degrees"),
               distance: float | None = Query(None, gt=0, allow_inf_nan=False,
                                              description="world units (default: the orbit radius); from 0.01x "
                                                          "to 50x the orbit radius"),
               size: int = Query(formats.ORBIT_SIZE, ge=16, description="pixels (square), at most "
                                                                        "--max-render-size")):
        if size > cfg.max_render_size:
            raise ApiError(422, f"size {size} is over the {cfg.max_render_size} px limit")
        folder, scene, b = _baked(sid)
        radius = float(scene.orbit.radius)
        if distance is not None and not RENDER_DISTANCE[0] * radius <= distance <= RENDER_DISTANCE[1] * radius:
            raise ApiError(422, f"distance {distance:g} is out of range ({RENDER_DISTANCE[0] * radius:.4g} to "
                                f"{RENDER_DISTANCE[1] * radius:.4g}: 0.01x to 50x the orbit radius)")
        return Response(render_png(scene, b, azimuth, elevation, distance, size, rcfg), media_type="image/png")

    @app.get("/v1/scenes/{sid}/views/{i}.png", summary="view i of the scene's orbit (as decode writes it)",
             response_class=Response, responses={200: {"content": {"image/png": {}}}})
    def view(sid: str, i: int):
        if not 0 <= i < formats.ORBIT_VIEWS:
            raise ApiError(404, f"view {i} does not exist (0..{formats.ORBIT_VIEWS - 1})")
        folder, scene, b = _baked(sid)
        _made(sid, orbit_view_png, folder, scene, b, i, rcfg)
        return Response(_read(sid, f"views/{i:03d}.png"), media_type="image/png")

    @app.get("/v1/scenes/{sid}/capture.png", summary="the rectified, colour-corrected capture the restore graph "
             "read (380x380 RGB; what `snapshot3d scan` writes)", response_class=Response,
             responses={200: {"content": {"image/png": {}}}})
    def capture(sid: str):
        return Response(_read(sid, "capture.png"), media_type="image/png")

    @app.get("/v1/scenes/{sid}/scene.s3d", summary="the scene file", response_class=Response,
             responses={200: {"content": {"application/octet-stream": {}}}})
    def scene_file(sid: str):
        return Response(_read(sid, "scene.s3d"), media_type="application/octet-stream",
                        headers={"Content-Disposition": f'attachment; filename="{sid}.s3d"'})

    @app.get("/v1/scenes/{sid}/mesh.glb", summary="the scene as a coloured mesh (glTF binary)",
             response_class=Response, responses={200: {"content": {"model/gltf-binary": {}}}})
    def mesh(sid: str):
        folder, scene, b = _baked(sid)
        _made(sid, mesh_file, folder, scene, b)
        return Response(_read(sid, "mesh.glb"), media_type="model/gltf-binary")

    @app.get("/v1/scenes/{sid}/grid", summary="the baked grid (binary, gzip; format in viewer/gridfile.py)",
             response_class=Response, responses={200: {"content": {"application/octet-stream": {}}}})
    def grid(sid: str, request: Request):
        data = _read(sid, "grid.bin.gz")
        if "gzip" not in request.headers.get("accept-encoding", ""):
            return Response(gzip.decompress(data), media_type="application/octet-stream")
        return Response(data, media_type="application/octet-stream", headers={"Content-Encoding": "gzip"})

    @app.get("/v1/models/{kind}.onnx", summary="the restore (file medium), restore-print, project and field graphs "
             "(docs/onnx-contract.md)", response_class=FileResponse)
    def model(kind: str):
        if kind not in MODEL_ROUTES:
            raise ApiError(404, f"no model {kind!r} ({', '.join(MODEL_ROUTES)})")
        codec = kind.removeprefix("restore-") if kind.startswith("restore-hinet") else None
        graph, _, decoder = kind.partition("-") if kind.startswith(("project-", "field-")) else (kind, "", None)
        path = model_path("restore", codec) if codec else model_path(graph, decoder=decoder)
        return FileResponse(path, media_type="application/octet-stream")

    @app.get("/v1/models/print-layout.npz", summary="the restore-print graph's layout inputs for one print codec and "
             "plane size (numpy .npz; docs/onnx-contract.md section 4)", response_class=Response,
             responses={200: {"content": {"application/octet-stream": {}}}})
    def print_layout_inputs(codec: str = Query(formats.PRINT_CODEC, description="the print codec the QR names"),
                            res: int = Query(..., description="plane resolution R (the QR's p=R,C)"),
                            channels: int = Query(..., description="plane channels C")):
        try:
            data = layout_npz(codec, res, channels)
        except (ValueError, OverflowError) as e:
            raise ApiError(422, str(e)) from None
        return Response(data, media_type="application/octet-stream",
                        headers={"Cache-Control": "public, max-age=86400"})

    @app.get("/", include_in_schema=False)
    def page():
        return FileResponse(STATIC / "index.html", media_type="text/html")

    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    return app
