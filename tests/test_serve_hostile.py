"""`snapshot3d serve` under hostile clients: everything a client controls (query, path, uploads, malformed
HTTP, slow bodies) answers 2xx, 4xx or 503 with {"error": "<one line>"} and one log line, never a 500; a
genuine bug answers a JSON 500 and keeps the connection. App-level cases through FastAPI's test client;
malformed HTTP through raw sockets to a real uvicorn (`viewer.serve_http`) on 127.0.0.1."""
import json
import logging
import socket
import threading
import time
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from helpers import bomb_png

from snapshot3d.viewer import serving
from snapshot3d.viewer.serve_config import ServeConfig
from snapshot3d.viewer.server import create_app

SNAPSHOT = Path(__file__).parent / "data" / "spot-snapshot.png"


def _json_error(r, status: int, match: str = ""):
    assert r.status_code == status, (r.status_code, r.text[:300])
    assert r.headers["content-type"].startswith("application/json"), r.headers
    body = r.json()
    assert set(body) == {"error"} and body["error"] and "\n" not in body["error"] and "Traceback" not in body["error"]
    assert match in body["error"], body["error"]


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hostile")
    app = create_app(ServeConfig(cache=str(tmp / "cache")))
    client = TestClient(app, raise_server_exceptions=False)
    r = client.post("/v1/decode", files={"file": ("spot.png", SNAPSHOT.read_bytes())})
    assert r.status_code == 200, r.text
    return client, r.json(), app


@pytest.mark.parametrize("params, match", [
    ({"distance": "1e-300"}, "distance"), ({"distance": "1e-9"}, "distance"), ({"distance": "nan"}, "distance"),
    ({"distance": "inf"}, "distance"), ({"distance": "1e309"}, "distance"), ({"distance": "1e6"}, "distance"),
    ({"distance": "0"}, "distance"), ({"azimuth": "nan"}, "azimuth"), ({"azimuth": "-inf"}, "azimuth"),
    ({"azimuth": "1e400"}, "azimuth"), ({"elevation": "NaN"}, "elevation"), ({"elevation": "90"}, "elevation"),
    ({"size": "abc"}, "size"), ({"size": "1e3"}, "size"), ({"size": "-5"}, "size"), ({"size": "8"}, "size"),
    ({"size": "99999999999999999999999999"}, "size"), ({"size": "12.5"}, "size"), ({"azimuth": ""}, "azimuth"),
])
def test_render_refuses_non_finite_and_degenerate_cameras(scene, params, match):
    client, body, _ = scene
    _json_error(client.get(body["render"], params=params), 422, match)


def test_render_within_the_distance_range_is_a_real_view(scene):
    client, body, _ = scene  # spot's orbit radius is 4.2: distances 0.042 to 210 are served
    views = []
    for d in ("0.05", "4.2", "200"):
        r = client.get(body["render"], params={"distance": d, "size": 32})
        assert r.status_code == 200, r.text
        views.append(cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_COLOR))
    assert all(v.shape == (32, 32, 3) for v in views) and views[1].std() > 5  # the scene, not a blank frame
    _json_error(client.get(body["render"], params={"distance": "0.04"}), 422, "0.04202 to 210.1")


def test_capture_is_the_snapshot_the_restore_read(scene):
    from snapshot3d.viewer.decode import read_input
    client, body, _ = scene
    r = client.get(body["capture"])
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    got = cv2.cvtColor(cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    assert got.shape == (380, 380, 3) and np.array_equal(got, read_input(SNAPSHOT)[1])


@pytest.mark.parametrize("path, status, match", [
    ("/v1/scenes/{sid}/views/abc.png", 422, "i"), ("/v1/scenes/{sid}/views/-1.png", 404, "view -1"),
    ("/v1/scenes/{sid}/views/99999999999999999999999.png", 404, "does not exist"),
    ("/v1/scenes/%00%00%00%00%00%00%00%00%00%00%00%00%00%00%00%00/grid", 404, "no scene"),
    ("/v1/scenes/" + "A" * 10000 + "/grid", 404, "no scene"), ("/v1/scenes/%E2%98%83/render", 404, "no scene"),
    ("/v1/scenes/..%2F..%2Fetc%2Fpasswd", 404, ""), ("/static/..%2F..%2Fserver.py", 404, ""),
    ("/static/%00", 404, ""), ("/v1/models/%00.onnx", 404, "no model"), ("/v1/models/..%2Fx.onnx", 404, ""),
    ("/v1/models/print-layout.npz?res=1e9&channels=4", 422, "res"),
    ("/v1/models/print-layout.npz?res=99999999999999999999&channels=4", 422, ""),
    ("/v1/models/print-layout.npz?res=16&channels=-1", 422, ""),
    ("/v1/models/print-layout.npz?res=16&channels=4&codec=%E2%98%83", 422, "codec"),
    ("/v1/models/print-layout.npz", 422, "res"),
])
def test_path_and_query_parameters(scene, path, status, match):
    client, body, _ = scene
    _json_error(client.get(path.replace("{sid}", body["scene_id"])), status, match)


def test_wrong_methods_answer_405_json_and_a_trailing_slash_404(scene):
    client, body, _ = scene
    _json_error(client.post("/healthz"), 405)
    _json_error(client.delete("/v1/decode"), 405)
    for path in ("/healthz/", f"/v1/scenes/{body['scene_id']}/", "/docs/", "/static"):  # no redirect to the Host
        _json_error(client.get(path, follow_redirects=False, headers={"Host": "evil.example"}), 404, "not found")


def _multipart(boundary=b"x", name=b"file", filename=b"a.png", data=b"data"):
    return (b"--" + boundary + b'\r\nContent-Disposition: form-data; name="' + name + b'"; filename="' + filename
            + b'"\r\nContent-Type: image/png\r\n\r\n' + data + b"\r\n--" + boundary + b"--\r\n")


def test_hostile_uploads(scene, tmp_path):
    client, _, app = scene
    png = SNAPSHOT.read_bytes()
    bomb_png(tmp_path / "bomb.png")
    cases = [  # (content, content-type, status, match)
        (_multipart(data=b""), "multipart/form-data; boundary=x", 415, "empty"),
        (_multipart(data=b"\x00" * 100), "multipart/form-data; boundary=x", 415, ""),
        (_multipart(data=png[:300]), "multipart/form-data; boundary=x", 422, ""),
        (_multipart(data=png[:5000]), "multipart/form-data; boundary=x", 422, ""),
        (_multipart(data=(tmp_path / "bomb.png").read_bytes()), "multipart/form-data; boundary=x", 413, "MP limit"),
        (_multipart(data=b"GIF89a" + b"\x00" * 50), "multipart/form-data; boundary=x", 415, ""),
        (_multipart(name=b"other"), "multipart/form-data; boundary=x", 422, "file"),
        (_multipart(filename=b"../../\xe2\x98\x83\x00.png", data=b"junk"), "multipart/form-data; boundary=x", 415, ""),
        (_multipart(), "multipart/form-data", 400, ""),  # no boundary
        (b"--x\r\ngarbage without headers", "multipart/form-data; boundary=x", 400, ""),
        (b'{"file": "a"}', "application/json", 422, "file"),
        (b"file=abc", "application/x-www-form-urlencoded", 422, "file"),
        (b"", "multipart/form-data; boundary=x", 422, "file"),
        (png, "image/png", 422, "file"),
    ]
    for content, ctype, status, match in cases:
        _json_error(client.post("/v1/decode", content=content, headers={"Content-Type": ctype}), status, match)
    store = app.state.store
    assert not list(store.root.glob(".uploads.*/*")) and not list(store.root.glob(".scene.*"))


def test_a_non_finite_report_is_refused_not_published(tmp_path, monkeypatch):
    real = serving.decode_scene

    def nan_report(path, cfg):
        ds = real(path, cfg)
        ds.report["quality_estimate"] = {"restore_psnr_expected_db": float("nan")}
        return ds
    monkeypatch.setattr(serving, "decode_scene", nan_report)
    app = create_app(ServeConfig(cache=str(tmp_path / "cache")))
    client = TestClient(app, raise_server_exceptions=False)
    _json_error(client.post("/v1/decode", files={"file": ("s.png", SNAPSHOT.read_bytes())}), 422,
                "report.quality_estimate.restore_psnr_expected_db came out as nan")
    assert app.state.store.ids() == []


def test_a_bug_answers_json_500_and_a_refusal_logs_one_line(tmp_path, monkeypatch, caplog):
    from snapshot3d.viewer import server as server_module

    def broken(folder, path, *a):
        raise RuntimeError("a bug")
    monkeypatch.setattr(server_module, "write_scene", broken)
    # raise_server_exceptions: the test client would raise if the exception went on past the answer
    client = TestClient(create_app(ServeConfig(cache=str(tmp_path / "cache"))), raise_server_exceptions=True)
    with caplog.at_level(logging.WARNING, logger="snapshot3d.serve"):
        _json_error(client.post("/v1/decode", files={"file": ("s.png", SNAPSHOT.read_bytes())}), 500, "RuntimeError")
        bug = [r for r in caplog.records if r.levelno == logging.ERROR]
        assert len(bug) == 1 and bug[0].exc_info is not None  # a bug keeps its traceback in the log
        caplog.clear()
        _json_error(client.get("/v1/scenes/nope/grid"), 404, "no scene")
    assert [(r.levelname, r.exc_info) for r in caplog.records] == [("WARNING", None)]
    assert "GET /v1/scenes/nope/grid -> 404" in caplog.records[0].getMessage()

    def oom(folder, path, *a):
        raise MemoryError()
    monkeypatch.setattr(server_module, "write_scene", oom)
    r = client.post("/v1/decode", files={"file": ("s.png", SNAPSHOT.read_bytes())})
    _json_error(r, 503, "memory")
    assert "Retry-After" in r.headers


def test_control_characters_in_a_path_stay_on_one_log_line(scene, caplog):
    client, _, _ = scene
    with caplog.at_level(logging.WARNING, logger="snapshot3d.serve"):
        _json_error(client.get("/nope%0AGET%20/forged%00"), 404, "GET /forged\\x00")
    assert len(caplog.records) == 1 and "\n" not in caplog.records[0].getMessage()


def test_an_evicted_scene_answers_404(tmp_path):
    app = create_app(ServeConfig(cache=str(tmp_path / "cache")))
    client = TestClient(app, raise_server_exceptions=False)
    body = client.post("/v1/decode", files={"file": ("s.png", SNAPSHOT.read_bytes())}).json()
    for name in ("report.json", "grid.bin.gz", "scene.s3d", "capture.png"):
        (app.state.store.root / body["scene_id"] / name).unlink()
    for link in (f"/v1/scenes/{body['scene_id']}", body["grid"], body["scene"], body["capture"]):
        _json_error(client.get(link), 404, "no ")


def test_serve_options_out_of_range_are_one_line_errors():
    from snapshot3d.errors import UserError
    for bad in ({"timeout_s": float("nan")}, {"max_upload_mb": float("inf")}, {"max_decodes": 0},
                {"read_timeout_s": -1.0}, {"max_header_kb": 1e9}, {"port": 70000}):
        with pytest.raises(UserError, match="--" + next(iter(bad)).replace("_", "-")):
            ServeConfig(**bad).checked()


# ---- malformed HTTP through raw sockets to a real uvicorn ----

@pytest.fixture(scope="module")
def live(tmp_path_factory):
    import uvicorn

    from snapshot3d.viewer.serve_http import json_protocol
    cfg = ServeConfig(cache=str(tmp_path_factory.mktemp("live") / "cache"), read_timeout_s=1.0,
                      header_timeout_s=1.0, max_header_kb=16)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    config = uvicorn.Config(create_app(cfg), host="127.0.0.1", port=port, log_level="warning",
                            http=json_protocol(cfg), h11_max_incomplete_event_size=int(cfg.max_header_kb * 1024))
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    for _ in range(200):
        if server.started:
            break
        time.sleep(0.05)
    yield port
    server.should_exit = True
    thread.join(10)


def _raw(port: int, data: bytes, wait: float = 5.0, close_write=False) -> tuple[int, dict, bytes, float]:
    """Send raw bytes; (status, headers, body, seconds to the answer) of the first answer."""
    t0 = time.monotonic()
    with socket.create_connection(("127.0.0.1", port), timeout=wait) as s:
        s.sendall(data)
        if close_write:
            s.shutdown(socket.SHUT_WR)
        buf = b""
        while b"\r\n\r\n" not in buf:
            chunk = s.recv(65536)
            if not chunk:
                break
            buf += chunk
        head, _, body = buf.partition(b"\r\n\r\n")
        lines = head.decode("latin-1").split("\r\n")
        headers = {k.strip().lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:])}
        n = int(headers.get("content-length", 0))
        while len(body) < n:
            chunk = s.recv(65536)
            if not chunk:
                break
            body += chunk
    return int(lines[0].split()[1]), headers, body, time.monotonic() - t0


def _raw_json(port, data, status, match="", **kw):
    got, headers, body, secs = _raw(port, data, **kw)
    assert got == status, (got, body[:200])
    assert headers["content-type"] == "application/json", headers
    err = json.loads(body)["error"]
    assert set(json.loads(body)) == {"error"} and "\n" not in err and match in err, err
    return secs


@pytest.mark.parametrize("request_bytes, status, match", [
    (b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: abc\r\n\r\n", 400, "Content-Length"),
    (b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: 1\r\nContent-Length: 2\r\n\r\nab", 400, "Content-Length"),
    (b"GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + b"a" * 200_000 + b"\r\n\r\n", 431, "16 kB"),
    (b"GET /\xff\xfe HTTP/1.1\r\nHost: x\r\n\r\n", 400, "illegal request line"),
    (b"HELLO THERE\r\n\r\n", 400, "malformed"),
    (b"GET / HTTP/1.1\r\nHost: x\r\nBad Header\r\n\r\n", 400, "malformed"),
    (b"GET / HTTP/1.1\r\n\r\n", 400, "Host"),
    (b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n5\r\nhello\r\n0\r\n\r\n", 411, "Content-Length"),
    (b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: 999999999999\r\n\r\n", 413, "MB limit"),
])
def test_malformed_http_answers_json(live, request_bytes, status, match):
    _raw_json(live, request_bytes, status, match)


def test_a_body_shorter_than_its_length_times_out_with_408(live):
    req = (b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; boundary=x\r\n"
           b"Content-Length: 5000\r\n\r\n--x\r\n")
    assert _raw_json(live, req, 408, "stopped arriving") < 4


def test_a_slow_head_times_out_with_408(live):
    assert _raw_json(live, b"GET /healthz HTTP/1.1\r\nHost: x\r\n", 408, "head") < 4
    assert _raw_json(live, b"", 408, "head") < 4  # a connection that sends nothing


def test_an_upgrade_request_is_answered_as_plain_http(live):
    got, headers, body, _ = _raw(live, b"GET /healthz HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n"
                                       b"Connection: Upgrade\r\n\r\n")
    assert got == 200 and json.loads(body)["ok"] is True


def _answers(port: int, requests: list) -> list:
    """(status, JSON body) of each request, sent one after another on one kept-alive connection."""
    out = []
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        f = s.makefile("rb")
        for req in requests:
            s.sendall(req)
            status = int(f.readline().split()[1])
            length = 0
            while (line := f.readline()) not in (b"\r\n", b""):
                if line.lower().startswith(b"content-length"):
                    length = int(line.split(b":")[1])
            out.append((status, json.loads(f.read(length))))
    return out


def test_a_refusal_keeps_the_connection_for_the_next_request(live):
    got = _answers(live, [b"GET /v1/scenes/nope HTTP/1.1\r\nHost: x\r\n\r\n", b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n"])
    assert [s for s, _ in got] == [404, 200] and "no scene" in got[0][1]["error"]


def test_a_bug_answers_json_500_and_keeps_the_connection(live, monkeypatch):
    from snapshot3d.viewer import server as server_module

    def broken(folder, path, *a):
        raise RuntimeError("a bug")
    monkeypatch.setattr(server_module, "write_scene", broken)
    body = _multipart(data=SNAPSHOT.read_bytes())
    upload = (b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; boundary=x\r\n"
              b"Content-Length: %d\r\n\r\n" % len(body) + body)
    got = _answers(live, [upload, b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n"])
    assert got[0] == (500, {"error": "internal error (RuntimeError); see the server's log"}) and got[1][0] == 200


def test_every_file_codec_graph_is_served(scene):
    """A client holding an older file snapshot fetches the graph its codec id names; the bytes are the shipped file."""
    from snapshot3d import formats
    from snapshot3d.viewer.runtime import model_path

    client = scene[0]
    for codec in formats.FILE_CODECS:
        r = client.get(f"/v1/models/restore-{codec}.onnx")
        assert r.status_code == 200 and r.content == model_path("restore", codec).read_bytes(), codec
    assert client.get("/v1/models/restore.onnx").content == model_path("restore").read_bytes()
    assert client.get("/v1/models/restore-hinet-9.onnx").status_code == 404
