"""`snapshot3d serve`: the scan-and-view HTTP API and the phone page (FastAPI; torch-free like the decode
path; OpenAPI at /docs). The work is in `viewer.serving`; this module maps it onto routes, limits and
one-line JSON errors ({"error": "..."}; never a stack trace).

Limits (`ServeConfig`): upload bytes (Content-Length checked before the body is read; 413), photo pixels
(read from the header before decoding; 413), concurrent decodes (a fixed number of slots; when all are
busy, 503 with Retry-After: never an unbounded queue), a per-decode time limit (503; the late result is
dropped, and its slot stays taken until it ends, so the bound holds), scenes kept (count and bytes,
least recently used evicted)."""
from __future__ import annotations

import asyncio
import gzip
import json
import logging
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
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from snapshot3d import __version__, formats
from snapshot3d.errors import UserError
from snapshot3d.print_feeds import layout_npz
from snapshot3d.scanner.imageio_safe import image_size

from .render import RenderConfig
from .runtime import model_path
from .serve_config import ServeConfig
from .serving import BakedCache, mesh_file, orbit_view_png, render_png, write_scene
from .store import SceneStore, StoreLimits

__all__ = ["ApiError", "create_app", "STATIC"]

STATIC = Path(__file__).resolve().parent / "static"
DECODE_PATH = "/v1/decode"
MODEL_ROUTES = ("restore", "restore-print", "project", "field")
log = logging.getLogger("snapshot3d.serve")


class ApiError(Exception):
    def __init__(self, status: int, message: str, headers: dict | None = None):
        super().__init__(message)
        self.status, self.message, self.headers = status, message, headers or {}


def _error(status: int, message: str, headers: dict | None = None) -> JSONResponse:
    return JSONResponse({"error": message.splitlines()[0] if message else "error"}, status, headers=headers)


class UploadLimit:
    """ASGI middleware: an upload to /v1/decode must state its length (411) within the limit (413); a
    body longer than its stated length is cut off (400). Checked before the body is read."""

    def __init__(self, app, max_bytes: int):
        self.app, self.max_bytes = app, max_bytes

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["path"] != DECODE_PATH or scope["method"] != "POST":
            return await self.app(scope, receive, send)
        length = dict(scope["headers"]).get(b"content-length")
        if length is None or not length.isdigit():
            return await _error(411, "the upload must state its Content-Length")(scope, receive, send)
        if int(length) > self.max_bytes:
            return await _error(413, f"upload of {int(length) / 1e6:.1f} MB is over the "
                                     f"{self.max_bytes / 1e6:.0f} MB limit")(scope, receive, send)
        seen = 0

        async def counted():
            nonlocal seen
            msg = await receive()
            seen += len(msg.get("body", b""))
            if seen > int(length):
                raise ApiError(400, "the upload is longer than its Content-Length")
            return msg
        return await self.app(scope, counted, send)


class Decoder:
    """Runs decodes on `max_decodes` threads, never more at once; `submit` refuses when all are busy."""

    def __init__(self, cfg: ServeConfig, store: SceneStore, baked: BakedCache):
        self.cfg, self.store, self.baked = cfg, store, baked
        self.pool = ThreadPoolExecutor(cfg.max_decodes, thread_name_prefix="decode")
        self.slots = threading.BoundedSemaphore(cfg.max_decodes)

    def busy(self) -> ApiError:
        return ApiError(503, f"busy: {self.cfg.max_decodes} decodes are running; retry shortly",
                        {"Retry-After": "2"})

    def _job(self, upload: Path, dropped: threading.Event) -> tuple[str, dict]:
        tmp = self.store.staging()
        try:
            ds = write_scene(tmp, upload)
            if dropped.is_set():
                raise ApiError(503, "dropped after the time limit")
            sid = self.store.publish(tmp)
            self.baked.put(sid, ds.scene, ds.baked)
            return sid, json.loads((self.store.root / sid / "report.json").read_text())
        finally:
            self.store.discard(tmp)
            shutil.rmtree(upload.parent, ignore_errors=True)
            self.slots.release()

    async def run(self, upload: Path) -> tuple[str, dict]:
        if not self.slots.acquire(blocking=False):
            shutil.rmtree(upload.parent, ignore_errors=True)
            raise self.busy()
        dropped = threading.Event()
        fut = self.pool.submit(self._job, upload, dropped)
        try:
            return await asyncio.wait_for(asyncio.wrap_future(fut), self.cfg.timeout_s)
        except asyncio.TimeoutError:
            dropped.set()
            raise ApiError(503, f"the decode took longer than the time limit ({self.cfg.timeout_s:g} s); retry later",
                           {"Retry-After": "5"}) from None


def _links(sid: str) -> dict:
    base = f"/v1/scenes/{sid}"
    return {"views": [f"{base}/views/{i}.png" for i in range(formats.ORBIT_VIEWS)], "render": f"{base}/render",
            "scene": f"{base}/scene.s3d", "mesh": f"{base}/mesh.glb", "grid": f"{base}/grid"}


def create_app(cfg: ServeConfig = ServeConfig()) -> FastAPI:
    store = SceneStore(cfg.cache_dir(), StoreLimits(cfg.max_scenes, cfg.max_cache_mb))
    baked = BakedCache(cfg.keep_baked)
    rcfg = RenderConfig(probe_div=cfg.render_probe_div, workers=1)  # one view on one thread: measured faster
    # than splitting it over threads (the work is short numpy calls), and it leaves the other cores to other requests
    decoder = Decoder(cfg, store, baked)
    uploads = Path(tempfile.mkdtemp(prefix=".uploads.", dir=store.root))
    app = FastAPI(title="snapshot3d", version=__version__,
                  description="Scan-and-view backend: upload a phone photo of a printed snapshot3d sheet, or a "
                              "snapshot file; get a scene id, its report and views; render any view on demand; "
                              "download the scene, the mesh or the baked grid. Errors are JSON "
                              '{"error": "<one line>"}.')
    app.state.config, app.state.store, app.state.decoder = cfg, store, decoder
    app.add_middleware(UploadLimit, max_bytes=int(cfg.max_upload_mb * 1e6))

    @app.exception_handler(ApiError)
    async def _api_error(request, e: ApiError):
        return _error(e.status, e.message, e.headers)

    @app.exception_handler(UserError)
    async def _user_error(request, e: UserError):
        return _error(422, str(e))

    @app.exception_handler(RequestValidationError)
    async def _invalid(request, e: RequestValidationError):
        first = e.errors()[0] if e.errors() else {}
        where = ".".join(str(p) for p in first.get("loc", ()) if p not in ("query", "path", "body"))
        return _error(422, f"invalid {where or 'request'}: {first.get('msg', 'malformed')}")

    @app.exception_handler(StarletteHTTPException)
    async def _http(request, e: StarletteHTTPException):
        return _error(e.status_code, str(e.detail) if e.status_code != 404 else f"not found: {request.url.path}")

    @app.exception_handler(Exception)
    async def _crash(request, e: Exception):
        log.exception("internal error on %s", request.url.path)
        return _error(500, f"internal error ({type(e).__name__}); see the server's log")

    def _folder(sid: str) -> Path:
        folder = store.folder(sid)
        if folder is None:
            raise ApiError(404, f"no scene {sid!r} (unknown, or evicted from the cache)")
        return folder

    @app.get("/healthz", summary="liveness and limits")
    def healthz():
        return {"ok": True, "version": __version__, "scenes": len(store.ids()), "limits": asdict(cfg)}

    @app.post(DECODE_PATH, summary="decode a phone photo of a sheet, or a snapshot file, into a scene")
    async def decode(file: UploadFile = File(..., description="JPEG or PNG: a photo of a printed sheet, or a "
                                                              "snapshot file (its metadata in its text or pixels)")):
        name = re.sub(r"[^A-Za-z0-9._-]", "_", Path(file.filename or "").name)[-80:].lstrip(".") or "upload"
        (uploads / (token := secrets.token_hex(8))).mkdir()
        path = uploads / token / name  # errors name the user's file, not a temporary one
        try:
            with path.open("wb") as f:
                while chunk := await file.read(1 << 20):
                    f.write(chunk)
            try:
                w, h, _ = image_size(path, "upload")
            except UserError as e:
                raise ApiError(413 if "pixels" in str(e) else 415, str(e)) from None
            if w * h > cfg.max_pixels_mp * 1e6:
                raise ApiError(413, f"photo of {w}x{h} pixels ({w * h / 1e6:.0f} MP) is over the "
                                    f"{cfg.max_pixels_mp:.0f} MP limit")
        except BaseException:
            shutil.rmtree(path.parent, ignore_errors=True)
            raise
        sid, report = await decoder.run(path)
        return {"scene_id": sid, "report": report, **_links(sid)}

    @app.get("/v1/scenes/{sid}", summary="a scene's report and links")
    def scene_info(sid: str):
        report = json.loads((_folder(sid) / "report.json").read_text())
        return {"scene_id": sid, "report": report, **_links(sid)}

    @app.get("/v1/scenes/{sid}/render", summary="one view rendered on demand (PNG)",
             response_class=Response, responses={200: {"content": {"image/png": {}}}})
    def render(sid: str, azimuth: float = Query(0.0, ge=-3600, le=3600, description="degrees; 0 = view 0"),
               elevation: float = Query(formats.ORBIT_ELEVATION_DEG, ge=-89.9, le=89.9, description="degrees"),
               distance: float | None = Query(None, gt=0, description="world units (default: the orbit radius)"),
               size: int = Query(formats.ORBIT_SIZE, ge=16, description="pixels (square)")):
        if size > cfg.max_render_size:
            raise ApiError(422, f"size {size} is over the {cfg.max_render_size} px limit")
        folder = _folder(sid)
        scene, b = baked.get(sid, folder)
        if distance is not None and distance > 50 * scene.orbit.radius:
            raise ApiError(422, f"distance {distance:g} is too far (at most 50x the orbit radius)")
        return Response(render_png(scene, b, azimuth, elevation, distance, size, rcfg), media_type="image/png")

    @app.get("/v1/scenes/{sid}/views/{i}.png", summary="view i of the scene's orbit (as decode writes it)",
             response_class=FileResponse)
    def view(sid: str, i: int):
        if not 0 <= i < formats.ORBIT_VIEWS:
            raise ApiError(404, f"view {i} does not exist (0..{formats.ORBIT_VIEWS - 1})")
        folder = _folder(sid)
        scene, b = baked.get(sid, folder)
        return FileResponse(orbit_view_png(folder, scene, b, i, rcfg), media_type="image/png")

    @app.get("/v1/scenes/{sid}/scene.s3d", summary="the scene file", response_class=FileResponse)
    def scene_file(sid: str):
        return FileResponse(_folder(sid) / "scene.s3d", media_type="application/octet-stream",
                            filename=f"{sid}.s3d")

    @app.get("/v1/scenes/{sid}/mesh.glb", summary="the scene as a coloured mesh (glTF binary)",
             response_class=FileResponse)
    def mesh(sid: str):
        folder = _folder(sid)
        scene, b = baked.get(sid, folder)
        return FileResponse(mesh_file(folder, scene, b), media_type="model/gltf-binary")

    @app.get("/v1/scenes/{sid}/grid", summary="the baked grid (binary, gzip; format in viewer/gridfile.py)",
             response_class=Response, responses={200: {"content": {"application/octet-stream": {}}}})
    def grid(sid: str, request: Request):
        data = (_folder(sid) / "grid.bin.gz").read_bytes()
        if "gzip" not in request.headers.get("accept-encoding", ""):
            return Response(gzip.decompress(data), media_type="application/octet-stream")
        return Response(data, media_type="application/octet-stream", headers={"Content-Encoding": "gzip"})

    @app.get("/v1/models/{kind}.onnx", summary="the restore (file medium), restore-print, project and field graphs "
             "(docs/onnx-contract.md)", response_class=FileResponse)
    def model(kind: str):
        if kind not in MODEL_ROUTES:
            raise ApiError(404, f"no model {kind!r} ({', '.join(MODEL_ROUTES)})")
        return FileResponse(model_path(kind), media_type="application/octet-stream")

    @app.get("/v1/models/print-layout.npz", summary="the restore-print graph's layout inputs for one print codec and "
             "plane size (numpy .npz; docs/onnx-contract.md section 4)", response_class=Response,
             responses={200: {"content": {"application/octet-stream": {}}}})
    def print_layout_inputs(codec: str = Query(formats.PRINT_CODEC, description="the print codec the QR names"),
                            res: int = Query(..., description="plane resolution R (the QR's p=R,C)"),
                            channels: int = Query(..., description="plane channels C")):
        try:
            data = layout_npz(codec, res, channels)
        except ValueError as e:
            raise ApiError(422, str(e)) from None
        return Response(data, media_type="application/octet-stream",
                        headers={"Cache-Control": "public, max-age=86400"})

    @app.get("/", include_in_schema=False)
    def page():
        return FileResponse(STATIC / "index.html", media_type="text/html")

    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    return app
