"""The HTTP server under `snapshot3d serve`: uvicorn with its h11 protocol, changed so that what never
reaches the app still answers JSON {"error": "<one line>"} (connection closed) with one log line:

- a request h11 rejects (a Content-Length of `abc`, two different Content-Lengths, a request line or
  header that is not HTTP, a non-ASCII target, a head over `max_header_kb`): 400, or 431 for the head's
  size, instead of uvicorn's plain-text 400 (its log line is replaced by one naming h11's reason);
- a request head that does not arrive within `header_timeout_s` of the connection opening or of the
  previous answer: 408 (uvicorn itself waits forever for a head that was started);
- a request to upgrade (e.g. to a WebSocket) is answered as plain HTTP, with one log line instead of two.

Documented in docs/serve-api.md, with what cannot be JSON."""
from __future__ import annotations

import json
import logging
import re

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from .serve_config import ServeConfig
from .serve_guard import one_line

__all__ = ["json_protocol", "raw_error", "run_server"]

log = logging.getLogger("snapshot3d.serve")
_REASONS = {400: b"Bad Request", 408: b"Request Timeout", 431: b"Request Header Fields Too Large"}


def raw_error(status: int, message: str) -> bytes:
    """A whole HTTP/1.1 answer with a JSON error body, closing the connection."""
    body = json.dumps({"error": one_line(message)}).encode()
    return (b"HTTP/1.1 %d %s\r\ncontent-type: application/json\r\ncontent-length: %d\r\nconnection: close\r\n\r\n"
            % (status, _REASONS.get(status, b"Error"), len(body)) + body)


class _OwnLine(logging.Filter):
    """Drops uvicorn's "Invalid HTTP request received." (the protocol below logs the reason instead)."""

    def filter(self, record) -> bool:
        return record.getMessage() != "Invalid HTTP request received."


def json_protocol(cfg: ServeConfig):
    """uvicorn's H11Protocol answering malformed or slow request heads in JSON (see the module's doc)."""
    head_s, max_kb = cfg.header_timeout_s, cfg.max_header_kb
    uv_log = logging.getLogger("uvicorn.error")
    if not any(isinstance(f, _OwnLine) for f in uv_log.filters):
        uv_log.addFilter(_OwnLine())

    class JsonH11Protocol(H11Protocol):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            self._head_timer = None
            self._head_error: h11.RemoteProtocolError | None = None
            next_event = self.conn.next_event

            def recorded():  # keep h11's reason for the JSON answer
                try:
                    return next_event()
                except h11.RemoteProtocolError as e:
                    self._head_error = e
                    raise
            self.conn.next_event = recorded

        def _refuse(self, status: int, message: str) -> None:
            if self.transport.is_closing():
                return
            log.warning("%s:%s -> %d %s", *(self.client or ("?", "?")), status, message)
            self.transport.write(raw_error(status, message))
            self.transport.close()

        def send_400_response(self, msg: str) -> None:
            e = self._head_error
            status = getattr(e, "error_status_hint", 400)
            if status == 431:
                self._refuse(431, f"malformed HTTP request: its head is over the {max_kb:g} kB limit")
            else:
                reason = re.sub(r":? *bytearray\(.*", "", one_line(str(e)) if e else msg)[:200]
                self._refuse(400, f"malformed HTTP request: {reason}")

        def _unsupported_upgrade_warning(self) -> None:  # uvicorn's two lines -> one
            log.warning("%s:%s upgrade %r not supported: answered as plain HTTP", *(self.client or ("?", "?")),
                        (self._get_upgrade() or b"").decode("latin-1")[:40])

        def handle_events(self) -> None:
            super().handle_events()
            self._arm()

        def connection_made(self, transport) -> None:
            super().connection_made(transport)
            self._arm()

        def connection_lost(self, exc) -> None:
            self._disarm()
            super().connection_lost(exc)

        def _arm(self) -> None:
            """A timer while a head is awaited (h11 IDLE with bytes of it in, or a fresh connection)."""
            waiting = self.conn.their_state is h11.IDLE and not self.transport.is_closing()
            if waiting and self._head_timer is None and (self.cycle is None or self.conn.trailing_data[0]):
                self._head_timer = self.loop.call_later(head_s, self._head_late)
            elif not waiting:
                self._disarm()

        def _disarm(self) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
                self._head_timer = None

        def _head_late(self) -> None:
            self._head_timer = None
            if self.conn.their_state is h11.IDLE:
                self._refuse(408, f"the request head did not arrive within {head_s:g} s")

    return JsonH11Protocol


def run_server(app, cfg: ServeConfig) -> None:
    """Serve `app` on cfg.host:cfg.port until interrupted (uvicorn, h11, the JSON protocol above)."""
    import uvicorn

    uvicorn.run(app, host=cfg.host, port=cfg.port, log_level="warning", http=json_protocol(cfg),
                h11_max_incomplete_event_size=int(cfg.max_header_kb * 1024), timeout_keep_alive=5)
