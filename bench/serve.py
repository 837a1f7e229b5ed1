"""`snapshot3d bench serve`: `snapshot3d serve` under load, and the page in headless Chromium.

- A live server (a `snapshot3d serve` subprocess on localhost, default limits) gets `--uploads` uploads at
  once, alternating the example photo (a print, scanned) and a snapshot file (tests/data/spot-snapshot.png).
  Each client tries once (first-try outcome: 200, or 503 with Retry-After), then retries after Retry-After
  until answered or `--deadline-s`. Checked: every request answered, no 5xx but 503, every 200 carries the
  scene of its own upload (its scene.s3d bytes equal the reference decode of that input: nothing lost or
  mixed up), scene ids unique. Measured: latency p50/p95 (upload to answer, retries included, and per
  successful attempt), the server's peak resident memory (VmHWM), `/render` latency of 380x380 views.
- Chromium (Debian's, via Playwright; skipped with a note when absent): time from choosing the example
  photo to the first view on the canvas, WebGL2 frame rate at 380x380 and at the 190x190 used while a
  finger moves, a snapshot PNG decoded in the page itself (onnxruntime-web: models, restore, bake), and
  screenshots of the page (serve_page.png, serve_page_turned.png, serve_page_local.png).

Writes serve.csv (one row per upload), serve.json, serve.png under --out."""
from __future__ import annotations

import hashlib
import json
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
import uuid
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from snapshot3d.paths import asset

from .common import pyplot, write_report

__all__ = ["bench_serve_command"]

SNAPSHOT = Path(__file__).resolve().parents[1] / "tests" / "data" / "spot-snapshot.png"
CHROMIUM = "/usr/bin/chromium"


def _free_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def _post(base: str, path: Path, timeout: float = 120.0) -> tuple[int, dict, object]:
    """multipart POST /v1/decode -> (status, json body, headers)"""
    boundary = uuid.uuid4().hex
    body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{path.name}\"\r\n"
            f"Content-Type: application/octet-stream\r\n\r\n").encode() + path.read_bytes() + f"\r\n--{boundary}--\r\n".encode()
    req = urllib.request.Request(base + "/v1/decode", body, {"Content-Type": f"multipart/form-data; boundary={boundary}"})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, json.loads(r.read()), r.headers
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"{}"), e.headers


def _get(base: str, url: str) -> bytes:
    with urllib.request.urlopen(base + url, timeout=60) as r:
        return r.read()


def _start_server(cache: str, port: int, *options: str):
    """A `snapshot3d serve` subprocess (extra `options` appended) -> (process, base URL, its log file).

    Its stderr goes to a file beside the cache folder, never to a pipe: the server logs one line per refusal,
    so a storm's 503s fill an unread pipe (64 kB) within seconds, and then the server's event loop blocks on
    that write and answers nobody (the stall of issue 39)."""
    log = Path(cache).with_name(Path(cache).name + ".log")
    with log.open("wb") as err:
        proc = subprocess.Popen([sys.executable, "-m", "snapshot3d", "serve", "--port", str(port), "--cache", cache,
                                 *options], stdout=subprocess.DEVNULL, stderr=err)
    base = f"http://127.0.0.1:{port}"
    for _ in range(600):
        try:
            _get(base, "/healthz")
            return proc, base, log
        except OSError:
            if proc.poll() is not None:
                raise RuntimeError(f"the server did not start: {log.read_text(errors='replace')[-500:]}")
            time.sleep(0.1)
    proc.kill()
    raise RuntimeError("the server did not answer /healthz within 60 s")


def _log_lines(log: Path) -> int:
    return log.read_bytes().count(b"\n") if log.is_file() else 0


def _peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _client(base: str, i: int, path: Path, deadline: float, t_start: float) -> dict:
    attempts, first, codes, retry_after = 0, None, [], True
    while True:
        t0 = time.perf_counter()
        status, body, headers = _post(base, path)
        attempts += 1
        codes.append(status)
        retry_after &= status != 503 or bool(headers.get("Retry-After"))
        first = first if first is not None else status
        if status != 503 or time.perf_counter() > deadline:
            break
        time.sleep(float(headers.get("Retry-After", 1)))
    t1 = time.perf_counter()
    return {"upload": i, "input": path.name, "first_status": first, "status": status, "attempts": attempts,
            "statuses": " ".join(map(str, codes)), "retry_after_on_503": retry_after,
            "latency_ms": (t1 - t_start) * 1e3, "attempt_ms": (t1 - t0) * 1e3,
            "scene_id": body.get("scene_id"), "source": (body.get("report") or {}).get("source"),
            "error": body.get("error")}


def _browser(base: str, out: Path) -> dict:
    from playwright.sync_api import sync_playwright

    args = ["--headless=new", "--no-sandbox", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", "--no-first-run", "--disable-quic"]
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=args)
        page = b.new_page(viewport={"width": 390, "height": 844}, is_mobile=True, has_touch=True)
        firsts = []
        for _ in range(3):
            page.goto(base + "/")
            page.set_input_files("#photo", str(asset("example-photo.jpg")))
            page.wait_for_function("window.snapshot3d.ready || window.snapshot3d.error", timeout=60000)
            firsts.append(page.evaluate("snapshot3d.firstViewMs"))
        page.wait_for_timeout(300)
        page.screenshot(path=str(out / "serve_page.png"))
        fps380 = [page.evaluate("snapshot3d.measureFps(20, 380)") for _ in range(3)]
        fps190 = [page.evaluate("snapshot3d.measureFps(20, 190)") for _ in range(3)]
        moving_size = page.evaluate("snapshot3d.chooseMovingSize()")  # what the page picked on this GL
        moving = [{"size": size, "fps_median": float(np.median([page.evaluate(f"snapshot3d.measureFps(20, {size})")
                                                                  for _ in range(3)])),
                   "psnr_vs_full_db": page.evaluate(f"snapshot3d.movingPsnr({size}, 6)")}
                  for size in sorted({190, 270, int(moving_size)})]
        renderer = page.evaluate("(() => { const g = document.createElement('canvas').getContext('webgl2'); "
                                 "const e = g.getExtension('WEBGL_debug_renderer_info'); "
                                 "return g.getParameter(e ? e.UNMASKED_RENDERER_WEBGL : g.RENDERER); })()")
        box = page.locator("#stage").bounding_box()
        x, y = box["x"] + box["width"] / 3, box["y"] + box["height"] / 2
        page.mouse.move(x, y)
        page.mouse.down()
        page.mouse.move(x + 160, y + 40, steps=8)
        page.mouse.up()
        page.wait_for_timeout(400)
        page.screenshot(path=str(out / "serve_page_turned.png"))
        local = []
        for _ in range(3):  # a snapshot PNG decoded in the page itself (onnxruntime-web), nothing uploaded
            page.goto(base + "/")
            page.set_input_files("#photo", str(SNAPSHOT))
            page.wait_for_function("window.snapshot3d.ready || window.snapshot3d.error", timeout=120000)
            local.append(page.evaluate("({source: snapshot3d.source, ...snapshot3d.local.timings_ms})"))
        page.screenshot(path=str(out / "serve_page_local.png"))
        b.close()
    return {"first_view_ms": firsts, "first_view_ms_median": float(np.median(firsts)),
            "fps_380": fps380, "fps_380_median": float(np.median(fps380)),
            "fps_190": fps190, "fps_190_median": float(np.median(fps190)), "webgl_renderer": renderer,
            "moving_size_chosen": moving_size, "moving_paths": moving,
            "local_decode": local, "local_decode_ms_median": float(np.median([sum(v for k, v in r.items() if k != "source")
                                                                               for r in local]))}


def bench_serve_command(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    inputs = [Path(asset("example-photo.jpg")), SNAPSHOT]
    cache = tempfile.mkdtemp(prefix="s3d-bench-serve-")
    proc, base, log = _start_server(cache, _free_port())
    try:
        reference = {}
        for path in inputs:  # one decode of each input alone: the scene every later answer must carry
            status, body, _ = _post(base, path)
            assert status == 200, body
            reference[path.name] = hashlib.sha256(_get(base, body["scene"])).hexdigest()
        t_start = time.perf_counter()
        deadline = t_start + args.deadline_s
        with ThreadPoolExecutor(args.uploads) as pool:
            rows = list(pool.map(lambda i: _client(base, i, inputs[i % 2], deadline, t_start), range(args.uploads)))
        wall = time.perf_counter() - t_start
        for r in rows:
            if r["status"] == 200:
                sha = hashlib.sha256(_get(base, f"/v1/scenes/{r['scene_id']}/scene.s3d")).hexdigest()
                r["own_scene"] = sha == reference[r["input"]]
        render_ms = []
        sid = next(r["scene_id"] for r in rows if r["status"] == 200 and r["input"] == inputs[0].name)
        for k in range(args.renders):
            t0 = time.perf_counter()
            _get(base, f"/v1/scenes/{sid}/render?azimuth={k * 360 / args.renders:.1f}&elevation=20&size=380")
            render_ms.append((time.perf_counter() - t0) * 1e3)
        peak = _peak_rss_mb(proc.pid)
        browser = _browser(base, out) if Path(CHROMIUM).exists() else {"skipped": f"{CHROMIUM} not installed"}
    finally:
        proc.terminate()
        proc.wait(10)
    ok = [r for r in rows if r["status"] == 200]
    first = [r["first_status"] for r in rows]
    statuses = [int(s) for r in rows for s in r["statuses"].split()]
    summary = {
        "uploads": args.uploads, "answered": len(rows), "wall_s": wall,
        "first_try": {str(s): first.count(s) for s in sorted(set(first))},
        "final": {str(s): sum(r["status"] == s for r in rows) for s in sorted({r["status"] for r in rows})},
        "every_503_had_retry_after": all(r["retry_after_on_503"] for r in rows),
        "other_5xx": sum(s >= 500 and s != 503 for s in statuses),
        "own_scene_all": all(r.get("own_scene") for r in ok), "unique_scene_ids": len({r["scene_id"] for r in ok}) == len(ok),
        "latency_ms_p50": float(np.percentile([r["latency_ms"] for r in ok], 50)) if ok else None,
        "latency_ms_p95": float(np.percentile([r["latency_ms"] for r in ok], 95)) if ok else None,
        "attempt_ms_p50": float(np.percentile([r["attempt_ms"] for r in ok], 50)) if ok else None,
        "peak_server_rss_mb": peak, "server_log_lines": _log_lines(log),  # one per refusal (each 503 included)
        "render_ms_median": float(np.median(render_ms)), "render_ms_p95": float(np.percentile(render_ms, 95)),
        "browser": browser,
    }
    shutil.rmtree(cache, ignore_errors=True)   # the server's scene cache and its log: nothing left in /tmp
    log.unlink(missing_ok=True)
    doc = write_report(out, "serve", rows, {
        "server": "snapshot3d serve, default limits (max_decodes 2)", "inputs": [p.name for p in inputs],
        "targets": {"render_ms_median": "<= 40", "client_fps_380": ">= 30, or the moving path at >= 30 with its "
                                                                  "PSNR against the full path reported",
                    "answered": "all (200, or 503 with Retry-After)", "peak_server_rss_mb": "<= 2048",
                    "other_5xx": 0, "first_view_ms": "<= 3000"},
        "summary": summary, "render_ms": render_ms})
    _chart(out / "serve.png", rows, render_ms, doc)
    print(json.dumps(summary, indent=2))
    return 0


def _chart(path: Path, rows: list[dict], render_ms: list[float], doc: dict) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for name in sorted({r["input"] for r in rows}):
        lat = sorted(r["latency_ms"] / 1e3 for r in rows if r["input"] == name and r["status"] == 200)
        ax[0].plot(lat, np.arange(1, len(lat) + 1) / len(lat), label=name)
    s = doc["summary"]
    ax[0].set(xlabel="upload to answer, retries included (s)", ylabel="fraction of uploads",
              title=f"{s['uploads']} uploads at once: first try {s['first_try']}")
    ax[0].legend()
    ax[1].hist(render_ms, bins=20)
    ax[1].axvline(40, color="C3", ls="--", label="target 40 ms")
    ax[1].set(xlabel="/render 380x380 (ms)", ylabel="requests",
              title=f"/render median {s['render_ms_median']:.0f} ms; peak server {s['peak_server_rss_mb']:.0f} MB; "
                    f"{doc['cores']} cores")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
