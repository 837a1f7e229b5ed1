"""`snapshot3d serve`'s API through FastAPI's test client: happy paths (photo and snapshot file), what each
link serves, every bad input of DESIGN section 7 as a one-line 4xx with nothing left in the cache, the
limits (upload bytes, pixels, busy, time limit) and least-recently-used eviction."""
import threading
import time
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from snapshot3d.paths import asset

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from helpers import bomb_png

from snapshot3d.viewer import server as server_module
from snapshot3d.viewer.gridfile import decode_grid
from snapshot3d.viewer.serve_config import ServeConfig
from snapshot3d.viewer.server import create_app

PHOTO = Path(asset("example-photo.jpg"))
SNAPSHOT = Path(__file__).parent / "data" / "spot-snapshot.png"


def _client(tmp_path, **kw):
    return TestClient(create_app(ServeConfig(cache=str(tmp_path / "cache"), **kw)))


def _post(client, path: Path, name=None, data=None):
    return client.post("/v1/decode", files={"file": (name or path.name, data if data is not None else path.read_bytes())})


def _cache_entries(tmp_path):
    """Every path under the cache but the (empty) uploads folder."""
    root = tmp_path / "cache"
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if not p.name.startswith(".uploads."))


def _one_line_error(r, status: int, match: str):
    assert r.status_code == status, (r.status_code, r.text)
    body = r.json()
    assert set(body) == {"error"} and "\n" not in body["error"] and "Traceback" not in body["error"], body
    assert match in body["error"], body["error"]


@pytest.fixture(scope="module")
def decoded(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("serve")
    client = _client(tmp)
    r = _post(client, PHOTO)
    assert r.status_code == 200, r.text
    return client, r.json()


def test_decode_photo_answers_scene_report_and_links(decoded):
    client, body = decoded
    rep = body["report"]
    assert len(body["scene_id"]) == 16 and rep["source"] == "photo of a sheet" and rep["detected"] is True
    assert rep["medium"] == "print" and rep["quality_estimate"]["restore_psnr_expected_db"] > 18
    assert set(rep["timings_ms"]) == {"scan", "restore", "bake", "quality"} and len(body["views"]) == rep["views"] == 20
    assert client.get(f"/v1/scenes/{body['scene_id']}").json()["report"] == rep


def test_views_render_on_demand_and_match_the_orbit(decoded):
    client, body = decoded
    view3 = client.get(body["views"][3])
    assert view3.status_code == 200 and view3.headers["content-type"] == "image/png"
    a = cv2.imdecode(np.frombuffer(view3.content, np.uint8), cv2.IMREAD_COLOR)
    same = client.get(body["render"], params={"azimuth": 54, "elevation": 20, "size": 380})  # view 3 of 20: 54 deg
    b = cv2.imdecode(np.frombuffer(same.content, np.uint8), cv2.IMREAD_COLOR)
    assert a.shape == (380, 380, 3) and np.array_equal(a, b)
    other = cv2.imdecode(np.frombuffer(client.get(body["render"], params={"azimuth": 140, "size": 200}).content,
                                       np.uint8), cv2.IMREAD_COLOR)
    assert other.shape == (200, 200, 3) and other.std() > 10  # a scene, not a blank frame
    near = client.get(body["render"], params={"azimuth": 54, "distance": 1.0})
    assert near.status_code == 200 and near.content != same.content


def test_downloads_scene_mesh_and_grid(decoded, tmp_path):
    from snapshot3d.scene import load_scene_file
    client, body = decoded
    (tmp_path / "s.s3d").write_bytes(client.get(body["scene"]).content)
    scene = load_scene_file(tmp_path / "s.s3d")
    assert sorted(body["report"]["planes"]) == sorted([scene.resolution, scene.channels])
    mesh = client.get(body["mesh"])
    assert mesh.status_code == 200 and mesh.content[:4] == b"glTF"
    raw = client.get(body["grid"], headers={"Accept-Encoding": "identity"}).content
    header, grid = decode_grid(raw)
    assert header["res"] == 96 and grid.shape == (96, 96, 96, 4)
    assert np.allclose(header["box"], scene.box, atol=1e-6) and header["orbit"]["radius"] == pytest.approx(scene.orbit.radius)
    gz = client.get(body["grid"], headers={"Accept-Encoding": "gzip"})
    assert gz.content == raw and len(gz.content) > 1e6  # the client unzipped what went over the wire as gzip


def test_a_client_restores_a_print_by_itself_from_the_served_graph_and_layout(decoded, tmp_path):
    """A phone app that restores on its own: the print restore graph and the layout its QR names, both from the
    server, in onnxruntime on the scan of the photo, give the planes of the scene the server decoded."""
    import io

    import onnxruntime as ort

    from snapshot3d.scene import load_scene_file, quantize_planes
    from snapshot3d.viewer.decode import read_input
    client, body = decoded
    res, channels = body["report"]["planes"]
    graph = client.get("/v1/models/restore-print.onnx")
    layout = client.get(f"/v1/models/print-layout.npz?codec={body['report']['codec']}&res={res}&channels={channels}")
    assert graph.status_code == layout.status_code == 200
    with np.load(io.BytesIO(layout.content)) as z:
        feeds = {k: z[k] for k in z.files}
    _, capture, _, _ = read_input(PHOTO)
    feeds["snapshot"] = (capture.astype(np.float32) / 255).transpose(2, 0, 1)[None]
    planes, reading = ort.InferenceSession(graph.content, providers=["CPUExecutionProvider"]).run(None, feeds)
    (tmp_path / "s.s3d").write_bytes(client.get(body["scene"]).content)
    assert planes.shape == (3, channels, res, res) and 0 < reading[2] < 1
    assert np.array_equal(quantize_planes(planes), load_scene_file(tmp_path / "s.s3d").codes)
    _one_line_error(client.get("/v1/models/print-layout.npz?codec=hinet-3&res=16&channels=4"), 422, "unknown print codec")
    _one_line_error(client.get("/v1/models/print-layout.npz?res=100&channels=4"), 422, "4x4 to 64x64")
    _one_line_error(client.get("/v1/models/nope.onnx"), 404, "restore-print")


def test_grid_file_round_trip_within_quantisation(decoded):
    from snapshot3d.scene import Orbit
    from snapshot3d.viewer.gridfile import LOGIT_FLOOR, encode_grid
    rng = np.random.default_rng(0)
    g = np.concatenate([rng.uniform(-20, 12, (8, 8, 8, 1)), rng.uniform(0, 1, (8, 8, 8, 3))], -1).astype(np.float32)
    header, back = decode_grid(encode_grid(g, [[-1, -1, -1], [1, 1, 1]], Orbit(3.0), 0.01))
    lo, hi = header["logit_range"]
    assert np.abs(back[..., 1:] - g[..., 1:]).max() <= 0.5 / 255 + 1e-6
    assert np.abs(back[..., 0] - np.clip(g[..., 0], LOGIT_FLOOR, None)).max() <= 0.5 * (hi - lo) / 255 + 1e-5
    assert back[0, 1, 2, 1] == pytest.approx(g[0, 1, 2, 1], abs=0.5 / 255)  # [ix, iy, iz] order kept
    with pytest.raises(ValueError, match="magic"):
        decode_grid(b"not a grid at all")


def test_decode_snapshot_file(tmp_path):
    client = _client(tmp_path)
    r = _post(client, SNAPSHOT)
    assert r.status_code == 200, r.text
    rep = r.json()["report"]
    assert rep["source"].startswith("snapshot file") and rep["medium"] == "file" and rep["scan"] is None


def test_bad_inputs_answer_one_line_4xx_and_leave_nothing(tmp_path):
    client = _client(tmp_path)
    grey = cv2.imencode(".png", np.full((600, 800, 3), 128, np.uint8))[1].tobytes()
    noise = cv2.imencode(".jpg", np.random.default_rng(0).integers(0, 255, (600, 800, 3), np.uint8))[1].tobytes()
    bomb_png(tmp_path / "bomb.png")
    cases = [("notes.txt", b"hello, not an image", 415, "not an image"),
             ("empty.jpg", b"", 415, "empty"),
             ("cut.jpg", PHOTO.read_bytes()[:20000], 422, "truncated JPEG"),
             ("grey.png", grey, 422, "washed out"),
             ("noise.jpg", noise, 422, "sheet"),
             ("bomb.png", (tmp_path / "bomb.png").read_bytes(), 413, "MP limit"),
             ("strip.png", cv2.imencode(".png", cv2.imread(str(SNAPSHOT))[:, :200])[1].tobytes(), 422, "sheet")]
    for name, data, status, match in cases:
        _one_line_error(client.post("/v1/decode", files={"file": (name, data)}), status, match)
    assert _cache_entries(tmp_path) == []
    assert not any((tmp_path / "cache").glob(".uploads.*/*")), "an upload was left behind"
    _one_line_error(client.post("/v1/decode", files={"other": ("a.jpg", b"x")}), 422, "file")
    _one_line_error(client.get("/v1/scenes/AAAAAAAAAAAAAAAA/grid"), 404, "no scene")
    _one_line_error(client.get("/v1/scenes/..%2F..%2Fetc/grid"), 404, "not found")
    _one_line_error(client.get("/nope"), 404, "not found")


def test_query_limits(decoded):
    client, body = decoded
    _one_line_error(client.get(body["render"], params={"size": 4096}), 422, "limit")
    _one_line_error(client.get(body["render"], params={"azimuth": "north"}), 422, "azimuth")
    _one_line_error(client.get(body["render"], params={"elevation": 95}), 422, "elevation")
    _one_line_error(client.get(body["render"], params={"distance": -1}), 422, "distance")
    _one_line_error(client.get(body["views"][0].replace("/0.png", "/20.png")), 404, "view 20")


def test_upload_and_pixel_limits(tmp_path):
    client = _client(tmp_path, max_upload_mb=0.05, max_pixels_mp=0.3)
    _one_line_error(_post(client, PHOTO), 413, "MB limit")  # the example photo is ~0.2 MB
    small = cv2.imencode(".jpg", np.zeros((600, 800, 3), np.uint8))[1].tobytes()  # 0.48 MP, a few kB
    _one_line_error(client.post("/v1/decode", files={"file": ("big.jpg", small)}), 413, "MP limit")
    chunked = client.post("/v1/decode", content=iter([b"--x\r\n"]), headers={"Content-Type": "multipart/form-data; boundary=x"})
    _one_line_error(chunked, 411, "Content-Length")
    assert _cache_entries(tmp_path) == []


def test_busy_answers_503_with_retry_after(tmp_path):
    app = create_app(ServeConfig(cache=str(tmp_path / "cache"), max_decodes=1))
    client = TestClient(app)
    decoder = app.state.decoder
    assert decoder.slots.acquire(blocking=False)  # one decode running
    try:
        r = _post(client, SNAPSHOT)
        _one_line_error(r, 503, "busy")
        assert int(r.headers["Retry-After"]) > 0
    finally:
        decoder.slots.release()
    assert _post(client, SNAPSHOT).status_code == 200  # the slot is free again


def test_time_limit_drops_the_late_result(tmp_path, monkeypatch):
    real, done = server_module.write_scene, threading.Event()

    def slow(folder, path, *a):
        time.sleep(1.5)
        try:
            return real(folder, path, *a)
        finally:
            done.set()
    monkeypatch.setattr(server_module, "write_scene", slow)
    client = _client(tmp_path, timeout_s=0.5)
    r = _post(client, SNAPSHOT)
    _one_line_error(r, 503, "time limit")
    assert "Retry-After" in r.headers
    assert done.wait(30)
    time.sleep(0.2)
    assert _cache_entries(tmp_path) == []  # the late scene was not published


def test_least_recently_used_scene_is_evicted(tmp_path):
    client = _client(tmp_path, max_scenes=2)
    ids = [_post(client, SNAPSHOT).json()["scene_id"] for _ in range(2)]
    time.sleep(0.05)
    assert client.get(f"/v1/scenes/{ids[0]}").status_code == 200  # the first is now the most recently used
    time.sleep(0.05)
    ids.append(_post(client, SNAPSHOT).json()["scene_id"])
    assert client.get(f"/v1/scenes/{ids[1]}").status_code == 404
    assert all(client.get(f"/v1/scenes/{i}").status_code == 200 for i in (ids[0], ids[2]))
    assert len(set(ids)) == 3 and client.get("/healthz").json()["scenes"] == 2


def test_openapi_and_page(decoded):
    client, _ = decoded
    paths = client.get("/openapi.json").json()["paths"]
    for p in ("/v1/decode", "/v1/scenes/{sid}/render", "/v1/scenes/{sid}/views/{i}.png", "/v1/scenes/{sid}/grid",
              "/v1/scenes/{sid}/scene.s3d", "/v1/scenes/{sid}/mesh.glb", "/healthz"):
        assert p in paths, p
    assert client.get("/docs").status_code == 200
    page = client.get("/")
    assert page.status_code == 200 and 'capture="environment"' in page.text
    for js in ("app.js", "gl.js", "grid.js", "style.css"):
        assert client.get(f"/static/{js}").status_code == 200, js


def test_serve_command_refuses_a_bad_cache_or_a_busy_port(tmp_path):
    import socket

    from helpers import assert_one_line_error, run_cli
    (tmp_path / "file").write_text("x")
    assert_one_line_error(run_cli("serve", "--cache", str(tmp_path / "file"), timeout=60), "scene cache")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        assert_one_line_error(run_cli("serve", "--port", str(port), "--cache", str(tmp_path / "c"), timeout=60),
                              "cannot listen")
