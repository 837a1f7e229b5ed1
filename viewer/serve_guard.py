"""The ASGI layer of `snapshot3d serve` between the server (uvicorn, `viewer.serve_http`) and the routes
(`viewer.server`): every answer it makes is JSON {"error": "<one line>"} with one log line.

`Guard` (the outermost middleware inside Starlette's own):
- request bodies: each piece must arrive within `read_timeout_s` and the whole body within
  `upload_timeout_s` (408, connection closed: a body shorter than its Content-Length never holds a worker);
- uploads (POST `upload_path`): a Content-Length is required (411), within `max_bytes` (413), and a body
  longer than it is refused (400); checked before the body is read;
- what escapes the routes: a client that went away is logged in one line; MemoryError answers 503; any
  other exception is a bug in the server: a JSON 500, its traceback in the log, the connection kept.

`BusyLog` keeps a storm of busy refusals (503, every decode slot taken) to one log line per 10 s."""
from __future__ import annotations

import asyncio
import logging
import threading
import time

from starlette.exceptions import HTTPException
from starlette.requests import ClientDisconnect
from starlette.responses import JSONResponse

__all__ = ["ApiError", "BusyLog", "Guard", "error_response", "log_refusal", "one_line", "printable"]

log = logging.getLogger("snapshot3d.serve")


class ApiError(HTTPException):
    """An answer other than 2xx, raised anywhere in a request (a Starlette HTTPException, so FastAPI lets
    it through its body parsing untouched)."""

    def __init__(self, status: int, message: str, headers: dict | None = None):
        super().__init__(status, message, headers)
        self.status, self.message = status, message


def printable(text: str, limit: int = 200) -> str:
    """A client's text (a path, a name) for a log line or a message: control characters escaped, cut."""
    text = str(text)[:limit]
    return text if text.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def one_line(message: str) -> str:
    lines = [ln.strip() for ln in str(message).splitlines() if ln.strip()]
    return (lines[0] if lines else "error")[:500]


def error_response(status: int, message: str, headers: dict | None = None) -> JSONResponse:
    return JSONResponse({"error": one_line(message)}, status, headers=headers)


def log_refusal(scope, status: int, message: str) -> None:
    """One log line per answer >= 400 (no traceback: the cause is the request)."""
    path = printable(scope.get("path", "?"))
    log.warning("%s %s -> %d %s", scope.get("method", "?"), path, status, one_line(message))


class BusyLog:
    """Busy refusals in at most one log line per `every_s` seconds: the first after a quiet spell as
    `log_refusal` writes it; those after it counted and summed up in one line once `every_s` has passed since
    the last line ("POST /v1/decode -> 503 refused 37 more uploads in 9.6 s: busy (2 decodes running)"),
    written by a timer (on the event loop when one runs), so that no count waits for the next refusal.
    Other refusals are not its business: they log one line each."""

    def __init__(self, every_s: float = 10.0, clock=time.monotonic):
        self.every_s, self.clock = every_s, clock
        self._lock = threading.Lock()
        self._last = None            # when the last line was written
        self._held, self._first = 0, 0.0   # refusals not logged yet; when the first of them came
        self._what = ("?", "?", 0)   # method, path, decodes running: for the summary line
        self._timer = None

    def refuse(self, scope, message: str, running: int) -> None:
        now = self.clock()
        with self._lock:
            quiet = self._held == 0 and (self._last is None or now - self._last >= self.every_s)
            if quiet:
                self._last = now
            else:
                self._held += 1
                if self._held == 1:
                    self._first = now
                self._what = (scope.get("method", "?"), printable(scope.get("path", "?")), running)
                schedule = self._timer is None
                if schedule:
                    self._timer = "scheduling"
        if quiet:
            log_refusal(scope, 503, message)
        elif schedule:
            self._schedule(max(self._last + self.every_s - now, 0.0))

    def _schedule(self, delay: float) -> None:
        try:
            self._timer = asyncio.get_running_loop().call_later(delay, self.flush)
        except RuntimeError:   # no event loop in this thread
            self._timer = threading.Timer(delay, self.flush)
            self._timer.daemon = True
            self._timer.start()

    def flush(self) -> None:
        """Write the summary line of the refusals held (none: nothing)."""
        now = self.clock()
        with self._lock:
            held, first, (method, path, running) = self._held, self._first, self._what
            self._held, self._timer = 0, None
            if held:
                self._last = now
        if held:
            log.warning("%s %s -> 503 refused %d more upload%s in %.1f s: busy (%d decodes running)", method, path,
                        held, "" if held == 1 else "s", max(now - first, 0.0), running)


class Guard:
    def __init__(self, app, upload_path: str, max_bytes: int, read_timeout_s: float, upload_timeout_s: float):
        self.app, self.upload_path, self.max_bytes = app, upload_path, max_bytes
        self.read_timeout_s, self.upload_timeout_s = read_timeout_s, upload_timeout_s

    async def _answer(self, scope, receive, send, status: int, message: str, headers: dict | None = None):
        log_refusal(scope, status, message)
        await error_response(status, message, headers)(scope, receive, send)

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        stated = None
        if scope["path"] == self.upload_path and scope["method"] == "POST":
            length = dict(scope["headers"]).get(b"content-length", b"")
            if not length.isdigit():
                return await self._answer(scope, receive, send, 411, "the upload must state its Content-Length")
            stated = int(length)
            if stated > self.max_bytes:
                return await self._answer(scope, receive, send, 413, f"upload of {stated / 1e6:.1f} MB is over the "
                                                                     f"{self.max_bytes / 1e6:g} MB limit")
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.upload_timeout_s
        body = {"seen": 0, "done": False}
        started = False

        async def receiving():
            if body["done"]:  # after the body: the app only listens for a disconnect; no limit on that wait
                return await receive()
            wait = min(self.read_timeout_s, deadline - loop.time())
            try:
                msg = await asyncio.wait_for(receive(), max(wait, 0.001))
            except asyncio.TimeoutError:
                raise ApiError(408, f"the request body stopped arriving (after {body['seen']} bytes; "
                                    f"{self.read_timeout_s:g} s per piece, {self.upload_timeout_s:g} s in all)",
                               {"Connection": "close"}) from None
            body["seen"] += len(msg.get("body", b""))
            body["done"] = msg["type"] != "http.request" or not msg.get("more_body", False)
            if stated is not None and body["seen"] > stated:
                raise ApiError(400, "the upload is longer than its Content-Length", {"Connection": "close"})
            return msg

        async def sending(msg):
            nonlocal started
            started = started or msg["type"] == "http.response.start"
            await send(msg)

        try:
            await self.app(scope, receiving, sending)
        except ClientDisconnect:
            log.warning("%s %s: the client went away before its request was read", scope["method"],
                        printable(scope["path"]))
        except MemoryError:
            if not started:
                await self._answer(scope, receive, send, 503, "out of memory for this request; retry later",
                                   {"Retry-After": "10"})
        except Exception as e:  # a bug in the server, not the client's doing
            log.error("internal error on %s %s", scope["method"], printable(scope["path"]), exc_info=e)
            if not started:
                await error_response(500, f"internal error ({type(e).__name__}); see the server's log")(
                    scope, receive, send)
