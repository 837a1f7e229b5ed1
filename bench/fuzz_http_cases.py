"""The requests of `bench fuzz`'s live-server campaign (`bench.fuzz_http.Live`): uploads of the file
inputs, multipart shapes, query and path parameters, malformed HTTP, slow bodies and heads, overload."""
from __future__ import annotations

import threading
import urllib.parse

from .fuzz_http import http_outcome, multipart
from .fuzz_inputs import mutate

__all__ = ["http_campaign"]

FLOATS = ["0", "-0", "1", "45.5", "nan", "NaN", "inf", "-inf", "1e309", "-1e309", "1e-300", "-1e-300", "1e300",
          "", " ", "abc", "0x10", "1_000", "１２", "%00", "3600", "3600.0001", "-3600", "89.9", "90", "-90", "1e3",
          "99999999999999999999999", "4.2", "0.05", "200", "1e-9", "true", "[1]", "1,2"]
INTS = ["16", "32", "15", "0", "-1", "1e3", "12.5", "abc", "", "99999999999999999999", "1024", "1025", "nan", "٣٢"]


def _get(live, target):
    try:
        return live.request("GET", target, timeout=60)
    except OSError:
        return None


def _at_once(job, n: int, join_s: float) -> None:
    """job(0) .. job(n - 1) on n threads at once; a job that fails with OSError leaves its answer None."""
    def guarded(i):
        try:
            job(i)
        except OSError:
            pass
    threads = [threading.Thread(target=guarded, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(join_s)


def http_campaign(live, seeds, file_inputs, rng, scale: float, record) -> None:
    """`record(cls, outcome, detail)` for every request."""
    body, headers = multipart("spot.png", seeds.snap_png)
    status, _, got = live.request("POST", "/v1/decode", body, headers, timeout=120)
    if status != 200:
        raise RuntimeError(f"the live server cannot decode the seed snapshot: {status} {got[:200]!r}")
    import json
    sid = json.loads(got)["scene_id"]
    record("http_seed", *http_outcome((status, {"content-type": "application/json"}, got)))

    with_files = [x for x in file_inputs if x.files and x.reader]
    picks = rng.choice(len(with_files), min(len(with_files), max(20, int(250 * scale))), replace=False)
    for i in picks:
        inp = with_files[int(i)]
        name = inp.arg.split("|")[0]
        data = inp.files.get(name, b"")
        if len(data) > 30e6:
            continue
        b, h = multipart(name, data)
        try:
            answer = live.request("POST", "/v1/decode", b, h, timeout=120)
        except OSError:
            answer = None
        record(inp.cls, *http_outcome(answer))

    shapes = {
        "no boundary": (multipart("a.png", seeds.snap_png)[0], {"Content-Type": "multipart/form-data"}),
        "json body": (b'{"file": 1}', {"Content-Type": "application/json"}),
        "urlencoded": (b"file=abc", {"Content-Type": "application/x-www-form-urlencoded"}),
        "empty multipart": (b"", {"Content-Type": "multipart/form-data; boundary=x"}),
        "garbage multipart": (b"--x\r\nnonsense", {"Content-Type": "multipart/form-data; boundary=x"}),
        "wrong field": (multipart("a.png", b"x")[0].replace(b'name="file"', b'name="other"'),
                        {"Content-Type": "multipart/form-data; boundary=fuzzboundary"}),
        "raw png": (seeds.snap_png, {"Content-Type": "image/png"}),
        "huge boundary": (b"--" + b"b" * 5000 + b"\r\n", {"Content-Type": "multipart/form-data; boundary=" + "b" * 5000}),
        "many parts": (b"".join(b'--x\r\nContent-Disposition: form-data; name="f%d"\r\n\r\nv\r\n' % i
                                for i in range(3000)) + b"--x--\r\n", {"Content-Type": "multipart/form-data; boundary=x"}),
        "two files": (multipart("a.png", b"x")[0][:-2] + multipart("b.png", seeds.snap_png)[0],
                      {"Content-Type": "multipart/form-data; boundary=fuzzboundary"}),
    }
    for mb in (24.9, 25.1):  # around --max-upload-mb (25): read and refused as not an image, or refused unread
        shapes[f"{mb} MB upload"] = multipart("big.png", b"\x89PNG" + bytes(int(mb * 1e6) - 300))
    for label, (b, h) in shapes.items():
        try:
            record("multipart_shape", *http_outcome(live.request("POST", "/v1/decode", b, h)))
        except OSError:
            record("multipart_shape", "dropped", label)

    q = urllib.parse.quote
    for _ in range(max(10, int(400 * scale))):
        params = {}
        for key, values in (("azimuth", FLOATS), ("elevation", FLOATS), ("distance", FLOATS), ("size", INTS)):
            if rng.random() < 0.5:
                params[key] = values[int(rng.integers(0, len(values)))]
        if params.get("size", "16") not in ("16", "32", "15", "1024") and rng.random() < 0.5:
            params["size"] = "16"
        params.setdefault("size", "16")
        target = f"/v1/scenes/{sid}/render?" + "&".join(f"{k}={q(v)}" for k, v in params.items())
        record("query_params", *http_outcome(_get(live, target)))
    for _ in range(max(5, int(120 * scale))):
        res, ch = INTS[int(rng.integers(0, len(INTS)))], INTS[int(rng.integers(0, len(INTS)))]
        codec = ["print-2", "print-1", "hinet-3", "", "☃", "x" * 1000][int(rng.integers(0, 6))]
        record("query_params", *http_outcome(_get(live, f"/v1/models/print-layout.npz?res={q(res)}&channels={q(ch)}"
                                                         f"&codec={q(codec)}")))
    sids = [sid, "A" * 16, "A" * 15, "A" * 10000, "%00" * 16, "..%2F..%2Fetc", "%E2%98%83" * 16, "a/b", "%2e%2e",
            "-" * 16, "_" * 16, "a%0Ab" * 4]
    suffixes = ["", "/render", "/views/0.png", "/views/19.png", "/views/20.png", "/views/-1.png", "/views/abc.png",
                "/views/1e3.png", "/views/99999999999999999999.png", "/scene.s3d", "/mesh.glb", "/grid", "/capture.png",
                "/nope", "/views/", "/views/0.jpg"]
    others = ["/", "/healthz", "/docs", "/openapi.json", "/static/app.js", "/static/..%2F..%2Fserver.py", "/static/%00",
              "/static/", "/v1/models/restore.onnx", "/v1/models/%00.onnx", "/v1/models/..%2F..%2Fx.onnx",
              "/v1/models/nope.onnx", "/v1", "/v1/scenes", "/v1/scenes/", "//", "/%ff", "/?%ff=%ff"]
    for _ in range(max(10, int(200 * scale))):
        s, suf = sids[int(rng.integers(0, len(sids)))], suffixes[int(rng.integers(0, len(suffixes)))]
        target = f"/v1/scenes/{s}{suf}" if rng.random() < 0.8 else others[int(rng.integers(0, len(others)))]
        if suf == "/mesh.glb" and s == sid and rng.random() < 0.7:
            target = "/healthz"
        method = "GET" if rng.random() < 0.85 else ["POST", "PUT", "DELETE", "PATCH", "OPTIONS", "HEAD"][int(rng.integers(0, 6))]
        try:
            record("path_params", *http_outcome(live.request(method, target), head=method == "HEAD"))
        except OSError:
            record("path_params", "dropped", target)

    good = b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n"
    malformed = [b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: abc\r\n\r\n",
                 b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: 1\r\nContent-Length: 2\r\n\r\nab",
                 b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: -1\r\n\r\n",
                 b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: 1e3\r\n\r\n",
                 b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: 99999999999999999999999\r\n\r\n",
                 b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: 5\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n",
                 b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n",
                 b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: gzip\r\n\r\n",
                 b"GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + b"a" * 200_000 + b"\r\n\r\n",
                 b"GET /" + b"a" * 100_000 + b" HTTP/1.1\r\nHost: x\r\n\r\n",
                 b"GET / HTTP/1.1\r\nHost: x\r\n" + b"X-A: b\r\n" * 20000 + b"\r\n",
                 b"GET /\xff\xfe HTTP/1.1\r\nHost: x\r\n\r\n", b"HELLO\r\n\r\n", b"\r\n\r\n\r\n", b"\x00" * 100,
                 b"GET / HTTP/9.9\r\nHost: x\r\n\r\n", b"GET / HTTP/1.1\r\n\r\n", b"GET / HTTP/1.0\r\n\r\n",
                 b"GET / HTTP/1.1\r\nHost: x\r\nBad Header\r\n\r\n", b"GET / HTTP/1.1\r\nHost: x\r\n: v\r\n\r\n",
                 b"GET / HTTP/1.1\r\nHost: x\r\nX: \x00\r\n\r\n", b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03",
                 b"GET http://evil/ HTTP/1.1\r\nHost: x\r\n\r\n", b"GET * HTTP/1.1\r\nHost: x\r\n\r\n",
                 b"CONNECT x:80 HTTP/1.1\r\nHost: x\r\n\r\n", b"GET / HTTP/1.1\nHost: x\n\n",
                 b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\r\n",
                 b"GET / HTTP/1.1\r\nHost: x\r\nExpect: 100-continue\r\n\r\n"]
    for data in malformed:
        record("malformed_http", *http_outcome(live.raw(data)))
    for _ in range(max(10, int(150 * scale))):
        record("malformed_http", *http_outcome(live.raw(mutate(good, rng, int(rng.integers(1, 6))))))

    slow = [b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; boundary=x\r\n"
            b"Content-Length: 5000\r\n\r\n--x\r\n", b"GET /healthz HTTP/1.1\r\nHost: x\r\n", b"",
            b"POST /v1/decode HTTP/1.1\r\nHost: x\r\nContent-Length: 10\r\n\r\nab", b"GE"]
    answers = [None] * len(slow)

    def one(i):
        answers[i] = live.raw(slow[i], timeout=15)
    _at_once(one, len(slow), 30)
    for a in answers:
        record("slow_body", *http_outcome(a))

    results = [None] * 6

    def upload(i):
        b, h = multipart("spot.png", seeds.snap_png)
        results[i] = live.request("POST", "/v1/decode", b, h, timeout=120)
    _at_once(upload, len(results), 180)
    for a in results:
        record("overload", *http_outcome(a))
