"""The phone page in real Chromium (Debian's, driven by Playwright): upload the example photo, wait for the
scene, drag it and see the canvas change, no console error; the WebGL2 view matches the server's /render of
the same pose; a photo that cannot be decoded shows why; without WebGL2 the page shows /render frames."""
import base64
import shutil
import socket
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from snapshot3d.metrics import psnr
from snapshot3d.paths import asset

CHROMIUM = "/usr/bin/chromium"
pytestmark = pytest.mark.skipif(shutil.which(CHROMIUM) is None,
                                reason="needs Debian's Chromium: apt-get install chromium (.ci/run installs it)")
ARGS = ["--headless=new", "--no-sandbox", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run", "--disable-quic"]
PHONE = {"viewport": {"width": 390, "height": 844}, "is_mobile": True, "has_touch": True}
NO_WEBGL2 = """const get = HTMLCanvasElement.prototype.getContext;
HTMLCanvasElement.prototype.getContext = function (kind, ...rest) { return kind === 'webgl2' ? null : get.call(this, kind, ...rest); };"""


@pytest.fixture(scope="module")
def base_url(tmp_path_factory):
    import uvicorn

    from snapshot3d.viewer.serve_config import ServeConfig
    from snapshot3d.viewer.server import create_app

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    server = uvicorn.Server(uvicorn.Config(create_app(ServeConfig(cache=str(tmp_path_factory.mktemp("serve-cache")))),
                                           host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    t0 = time.time()
    while not server.started:
        assert time.time() - t0 < 30 and thread.is_alive(), "the server did not start"
        time.sleep(0.05)
    yield f"http://127.0.0.1:{port}"
    server.should_exit = True
    thread.join(10)


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


def _page(browser, base_url, init_script=None):
    page = browser.new_page(**PHONE)
    errors = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    if init_script:
        page.add_init_script(init_script)
    page.goto(base_url + "/")
    return page, errors


def _upload(page, path, timeout_ms=30000):
    page.set_input_files("#photo", str(path))
    page.wait_for_function("window.snapshot3d.ready || window.snapshot3d.error", timeout=timeout_ms)


def _canvas(page) -> np.ndarray:
    url = page.evaluate("document.getElementById('view').toDataURL('image/png')")
    return cv2.imdecode(np.frombuffer(base64.b64decode(url.split(",", 1)[1]), np.uint8), cv2.IMREAD_COLOR)


def _drag(page, dx=150, dy=30):
    box = page.locator("#stage").bounding_box()
    x, y = box["x"] + box["width"] / 3, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + dx, y + dy, steps=6)
    page.mouse.up()
    page.wait_for_timeout(400)  # the page redraws at full size 200 ms after the last move


def test_upload_view_and_drag(browser, base_url, tmp_path):
    page, errors = _page(browser, base_url)
    _upload(page, asset("example-photo.jpg"))
    state = page.evaluate("({mode: snapshot3d.mode, error: snapshot3d.error, first: snapshot3d.firstViewMs})")
    assert state["error"] is None and state["mode"] == "webgl2", state
    assert state["first"] < 10000  # the 3 s target is measured by `bench serve` on a quiet machine
    assert "Expected quality" in page.inner_text("#quality")
    before = _canvas(page)
    assert before.shape == (380, 380, 3) and before.std() > 10
    _drag(page)
    after = _canvas(page)
    pose = page.evaluate("[snapshot3d.azimuth, snapshot3d.elevation]")
    assert pose[0] != 0 and pose[1] != 20, pose
    assert np.abs(after.astype(int) - before.astype(int)).mean() > 3, "dragging did not turn the scene"
    page.screenshot(path=str(tmp_path / "page.png"))
    assert errors == [], errors


def test_client_render_matches_server_render(browser, base_url):
    import urllib.request

    page, errors = _page(browser, base_url)
    _upload(page, asset("example-photo.jpg"))
    for az, el in ((30.0, 20.0), (200.0, -10.0)):
        page.evaluate(f"snapshot3d.pose({az}, {el})")
        client = _canvas(page)
        sid = page.evaluate("snapshot3d.sceneId")
        png = urllib.request.urlopen(f"{base_url}/v1/scenes/{sid}/render?azimuth={az}&elevation={el}&size=380").read()
        server = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
        score = psnr(client.astype(np.float32) / 255, server.astype(np.float32) / 255)
        assert score > 40, f"WebGL2 and the server disagree at azimuth {az}: {score:.1f} dB"
    assert errors == [], errors


def test_moving_path_is_chosen_per_device_and_scored(browser, base_url):
    """While a finger moves the page draws fewer rays (issue 39): the size comes from this GL's own frame rate
    and `movingPsnr` scores it against the full frames (the same size scores as identical)."""
    page, errors = _page(browser, base_url)
    _upload(page, asset("example-photo.jpg"))
    page.wait_for_function("snapshot3d.movingChosen", timeout=10000)
    size = page.evaluate("snapshot3d.chooseMovingSize()")
    assert 160 <= size <= 380, size
    assert page.evaluate("snapshot3d.movingPsnr(380, 2)") > 100   # the full path against itself
    half = page.evaluate("snapshot3d.movingPsnr(190, 2)")
    assert 20 < half < 60, half                                      # softer, still the same scene
    assert page.evaluate("[document.getElementById('view').width, snapshot3d.azimuth]") == [380, 0]
    assert errors == [], errors


def test_undecodable_photo_says_why(browser, base_url, tmp_path):
    grey = tmp_path / "wall.jpg"
    cv2.imwrite(str(grey), np.full((600, 800, 3), 128, np.uint8))
    page, _ = _page(browser, base_url)
    _upload(page, grey)
    text = page.inner_text("#status")
    assert "Could not decode" in text and "washed out" in text, text
    assert page.evaluate("snapshot3d.ready") is False


def test_without_webgl2_the_server_renders_frames(browser, base_url):
    page, errors = _page(browser, base_url, NO_WEBGL2)
    _upload(page, Path(__file__).parent / "data" / "spot-snapshot.png")
    assert page.evaluate("snapshot3d.mode") == "frames"
    page.wait_for_function("document.getElementById('frame').complete && snapshot3d.frames > 0", timeout=20000)
    src0 = page.get_attribute("#frame", "src")
    _drag(page)
    page.wait_for_function(f"document.getElementById('frame').src !== {src0!r} && document.getElementById('frame').complete",
                           timeout=20000)
    assert "/render?azimuth=" in page.get_attribute("#frame", "src")
    assert page.evaluate("document.getElementById('frame').naturalWidth") == 380
    assert errors == [], errors


@pytest.fixture(scope="module")
def file_4x(tmp_path_factory) -> Path:
    """The example snapshot as `embed` writes a file today: 4x its size, each pixel a 4 x 4 square."""
    from snapshot3d import formats
    from snapshot3d.scanner.snapfile import read_snapshot, write_snapshot

    rgb, meta = read_snapshot(Path(__file__).parent / "data" / "spot-snapshot.png")
    path = tmp_path_factory.mktemp("page") / "spot-snapshot-4x.png"
    write_snapshot(path, rgb, meta, scale=formats.FILE_SCALE)
    return path


def test_square_means_round_as_opencv(browser, base_url):
    """The page shrinks a file written k times larger by the means of its squares exactly as the Python
    decode does (OpenCV's INTER_AREA, whose ties round half up at k = 2 and half to even otherwise)."""
    page, errors = _page(browser, base_url)
    rng = np.random.default_rng(0)
    for k in (1, 2, 3, 4):
        rgb = rng.integers(0, 256, (380 * k, 380 * k, 3), dtype=np.uint8)
        rgba = np.dstack([rgb, np.full(rgb.shape[:2], 255, np.uint8)])
        got = page.evaluate("""([b64, k]) => {
            const x = S3DLocal.squareMeans(Uint8Array.from(atob(b64), (c) => c.charCodeAt(0)), k);
            const out = new Uint8Array(x.length);
            for (let i = 0; i < x.length; i++) out[i] = Math.round(x[i] * 255);
            let bin = "";
            for (let i = 0; i < out.length; i += 8192) bin += String.fromCharCode(...out.subarray(i, i + 8192));
            return btoa(bin);
        }""", [base64.b64encode(rgba.tobytes()).decode(), k])
        mine = np.frombuffer(base64.b64decode(got), np.uint8).reshape(3, 380, 380).transpose(1, 2, 0)
        want = cv2.resize(rgb, (380, 380), interpolation=cv2.INTER_AREA) if k > 1 else rgb
        assert np.array_equal(mine, want), f"k={k}: {int((mine != want).sum())} values differ from OpenCV's"
    assert page.evaluate("[S3DLocal.pngSize(new Uint8Array(8).buffer), "
                         "S3DLocal.pngSize(new Uint8Array(24).buffer)]") == [None, None]
    assert errors == [], errors


@pytest.mark.parametrize("which", ["380 px", "4x"])
def test_snapshot_png_decodes_in_the_browser_like_python(browser, base_url, file_4x, which):
    """A dropped snapshot PNG is restored, unspread and baked in the page (onnxruntime-web): nothing is
    uploaded, and the grid it bakes is the one the Python decode bakes for the same file. The file as
    `embed` writes it (4x, each pixel a square) decodes in the page too."""
    import httpx

    snapshot = Path(__file__).parent / "data" / "spot-snapshot.png" if which == "380 px" else file_4x
    page, errors = _page(browser, base_url)
    posts = []
    page.on("request", lambda r: posts.append(r.url) if r.method == "POST" else None)
    _upload(page, snapshot, timeout_ms=120000)
    state = page.evaluate("({source: snapshot3d.source, mode: snapshot3d.mode, error: snapshot3d.error, "
                          "evaluated: snapshot3d.local && snapshot3d.local.evaluated})")
    assert state["error"] is None and state["source"] == "browser" and state["mode"] == "webgl2", state
    assert posts == [], f"the page uploaded the snapshot: {posts}"
    body = httpx.post(base_url + "/v1/decode", files={"file": (snapshot.name, snapshot.read_bytes())}, timeout=60).json()
    assert state["evaluated"] == body["report"]["field_evaluations"]
    diff = page.evaluate("""async (url) => {
        const server = S3DGrid.parse(await (await fetch(url)).arrayBuffer()), mine = snapshot3d.local;
        let differ = 0, maxDiff = 0;
        for (let i = 0; i < mine.cells.length; i++) {
            const d = Math.abs(mine.cells[i] - server.cells[i]);
            if (d) { differ++; maxDiff = Math.max(maxDiff, d); }
        }
        return {differ, maxDiff, n: mine.cells.length, range: [mine.header.logit_range, server.header.logit_range],
                step: [mine.header.step, server.header.step]};
    }""", base_url + body["grid"])
    assert diff["differ"] / diff["n"] < 1e-3 and diff["maxDiff"] <= 2, diff
    assert diff["range"][0] == pytest.approx(diff["range"][1], abs=1e-3), diff
    assert diff["step"][0] == pytest.approx(diff["step"][1], rel=1e-5), diff
    # the views: the page's renderer on its own grid and on the server's grid, the same pose
    page.evaluate("snapshot3d.pose(30, 20)")
    theirs = page.evaluate("""async (url) => {
        const server = S3DGrid.parse(await (await fetch(url)).arrayBuffer());
        const canvas = document.createElement("canvas");
        canvas.width = canvas.height = 380;
        S3DGL.create(canvas, server).draw(30, 20, server.header.orbit.radius);
        return canvas.toDataURL("image/png");
    }""", base_url + body["grid"])
    theirs = cv2.imdecode(np.frombuffer(base64.b64decode(theirs.split(",", 1)[1]), np.uint8), cv2.IMREAD_COLOR)
    score = psnr(_canvas(page).astype(np.float32) / 255, theirs.astype(np.float32) / 255)
    assert score > 50, f"the browser's decode and the server's give different views: {score:.1f} dB"
    assert errors == [], errors
