"""The live-server part of `snapshot3d bench fuzz`: `snapshot3d serve` as a subprocess on a free port of
127.0.0.1, hit with mutated uploads, crafted query and path parameters, and malformed HTTP over raw
sockets (bounded loops; the server is stopped at the end).

Outcomes: ok (2xx), error (4xx or 503 with {"error": "<one line>"}), 5xx (any other 5xx), nonjson (an error
not in that shape), dropped (no answer: the connection closed or timed out), nonfinite (a 2xx JSON body
with NaN/inf)."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["Live", "http_outcome"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Live:
    """`snapshot3d serve` in a subprocess, stderr kept in a file; a context manager."""

    def __init__(self, root: Path, read_timeout_s: float = 1.5, header_timeout_s: float = 1.5):
        self.port, self.root = free_port(), root
        self.args = ["--port", str(self.port), "--cache", str(root / "cache"), "--read-timeout-s",
                     str(read_timeout_s), "--header-timeout-s", str(header_timeout_s), "--max-decodes", "2"]

    def __enter__(self):
        self.log = open(self.root / "serve.log", "wb")
        self.proc = subprocess.Popen([sys.executable, "-m", "snapshot3d", "serve", *self.args],
                                     stdout=subprocess.DEVNULL, stderr=self.log)
        for _ in range(600):
            try:
                status, _, _ = self.request("GET", "/healthz")
                if status == 200:
                    return self
            except OSError:
                pass
            if self.proc.poll() is not None:
                raise RuntimeError(f"snapshot3d serve exited: {(self.root / 'serve.log').read_text()[-500:]}")
            time.sleep(0.1)
        raise RuntimeError("snapshot3d serve did not start in 60 s")

    def peak_mb(self) -> float:
        try:
            for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
        except OSError:
            pass
        return float("nan")

    def __exit__(self, *exc):
        self.proc.terminate()
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.log.close()

    def log_text(self) -> str:
        return (self.root / "serve.log").read_text(errors="replace")

    def request(self, method: str, target: str, body: bytes = b"", headers: dict | None = None, timeout=60.0):
        """(status, headers, body) of one request on a fresh connection (http.client)."""
        import http.client
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=timeout)
        try:
            conn.request(method, target, body=body or None, headers=headers or {})
            r = conn.getresponse()
            return r.status, {k.lower(): v for k, v in r.getheaders()}, r.read()
        finally:
            conn.close()

    def raw(self, data: bytes, timeout: float = 10.0, pause_after: float = 0.0):
        """(status, headers, body) of the first answer to raw bytes, or None when the server answered nothing."""
        with socket.create_connection(("127.0.0.1", self.port), timeout=timeout) as s:
            try:
                s.sendall(data)
            except OSError:
                pass
            buf = b""
            try:
                while b"\r\n\r\n" not in buf:
                    chunk = s.recv(65536)
                    if not chunk:
                        return None
                    buf += chunk
                head, _, body = buf.partition(b"\r\n\r\n")
                lines = head.decode("latin-1").split("\r\n")
                headers = {k.strip().lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:])}
                n = int(headers.get("content-length", "0") or 0)
                while len(body) < n:
                    chunk = s.recv(65536)
                    if not chunk:
                        break
                    body += chunk
                return int(lines[0].split()[1]), headers, body
            except (socket.timeout, ConnectionError, ValueError, IndexError):
                return None


def http_outcome(answer, head: bool = False) -> tuple[str, str]:
    """The outcome of one answer; `head`: the request was HEAD (no body to check)."""
    if answer is None:
        return "dropped", "no answer"
    status, headers, body = answer
    if head:
        json_type = headers.get("content-type", "").startswith("application/json")
        if status >= 500 and status != 503:
            return "5xx", f"{status} (HEAD)"
        return ("ok", "") if status < 300 else ("error", f"{status} (HEAD)") if json_type or status < 400 \
            else ("nonjson", f"{status} {headers.get('content-type')} (HEAD)")
    if 200 <= status < 300:
        if headers.get("content-type", "").startswith("application/json"):
            try:
                json.loads(body, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
            except ValueError:
                return "nonfinite", body[:100].decode("latin-1")
        return "ok", ""
    try:
        err = json.loads(body)
        shaped = set(err) == {"error"} and isinstance(err["error"], str) and "\n" not in err["error"]
    except (ValueError, TypeError):
        shaped, err = False, {}
    if status >= 500 and status != 503:
        return "5xx", f"{status} {body[:100].decode('latin-1')}"
    if not shaped or not headers.get("content-type", "").startswith("application/json"):
        return "nonjson", f"{status} {headers.get('content-type')} {body[:80]!r}"
    return "error", f"{status} {err['error'][:120]}"


def multipart(name: str, data: bytes, boundary: str = "fuzzboundary") -> tuple[bytes, dict]:
    b = boundary.encode()
    safe = name.encode("utf-8", "replace").replace(b'"', b"_").replace(b"\r", b"_").replace(b"\n", b"_")
    body = (b"--" + b + b'\r\nContent-Disposition: form-data; name="file"; filename="' + safe
            + b'"\r\nContent-Type: application/octet-stream\r\n\r\n' + data + b"\r\n--" + b + b"--\r\n")
    return body, {"Content-Type": f"multipart/form-data; boundary={boundary}", "Content-Length": str(len(body))}


def tmp_root() -> Path:
    return Path(tempfile.mkdtemp(prefix="fuzz-serve-", dir=os.environ.get("TMPDIR")))
