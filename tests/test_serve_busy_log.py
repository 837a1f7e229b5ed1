"""A storm of busy refusals (503, every decode slot taken) logs one line, then at most one summary line per
`BusyLog.every_s` with the count, so that no refusal goes uncounted; other refusals log one line each."""
import logging
import re
import time
import warnings
from pathlib import Path

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from snapshot3d.viewer.serve_config import ServeConfig
from snapshot3d.viewer.serve_guard import BusyLog
from snapshot3d.viewer.server import create_app

SNAPSHOT = Path(__file__).parent / "data" / "spot-snapshot.png"
SCOPE = {"method": "POST", "path": "/v1/decode"}
SUMMARY = re.compile(r"POST /v1/decode -> 503 refused (\d+) more uploads? in [\d.]+ s: busy \((\d+) decodes running\)")


def _lines(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "snapshot3d.serve"]


def _refusals_counted(lines: list[str]) -> int:
    """Each full busy line is one refusal; a summary line counts its N."""
    full = sum(1 for s in lines if s.startswith("POST /v1/decode -> 503 busy:"))
    return full + sum(int(m.group(1)) for s in lines if (m := SUMMARY.search(s)))


def test_a_burst_logs_one_line_then_one_summary(caplog):
    caplog.set_level(logging.WARNING, logger="snapshot3d.serve")
    busy = BusyLog(every_s=0.3)
    t0 = time.monotonic()
    for _ in range(100):
        busy.refuse(SCOPE, "busy: 2 decodes are running; retry shortly", 2)
    burst_s = time.monotonic() - t0
    assert _lines(caplog) == ["POST /v1/decode -> 503 busy: 2 decodes are running; retry shortly"]
    time.sleep(0.8)   # the timer writes the summary without waiting for another refusal
    lines = _lines(caplog)
    assert 2 <= len(lines) <= 3 + burst_s / 0.3 and all(SUMMARY.search(s) for s in lines[1:]), lines
    assert _refusals_counted(lines) == 100 and SUMMARY.search(lines[-1]).group(2) == "2"
    busy.refuse(SCOPE, "busy: 2 decodes are running; retry shortly", 2)   # after a quiet spell: in full again
    assert _lines(caplog)[-1].startswith("POST /v1/decode -> 503 busy:") and _refusals_counted(_lines(caplog)) == 101


def test_the_server_logs_a_storm_of_busy_uploads_in_two_lines_and_other_errors_each(tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="snapshot3d.serve")
    app = create_app(ServeConfig(cache=str(tmp_path / "cache"), max_decodes=2))
    app.state.busy_log.every_s = 1.0
    decoder, data = app.state.decoder, SNAPSHOT.read_bytes()
    with TestClient(app) as client:
        assert decoder.slots.acquire(blocking=False) and decoder.slots.acquire(blocking=False)  # 2 decodes running
        try:
            t0 = time.monotonic()
            got = [client.post("/v1/decode", files={"file": ("s.png", data)}) for _ in range(60)]
            burst_s = time.monotonic() - t0
            junk = [client.post("/v1/decode", files={"file": ("junk.png", b"not an image")}) for _ in range(5)]
        finally:
            decoder.slots.release()
            decoder.slots.release()
        assert [r.status_code for r in got] == [503] * 60 and all(r.headers["Retry-After"] for r in got)
        assert all(r.json()["error"].startswith("busy: 2 decodes") for r in got)
        assert [r.status_code for r in junk] == [415] * 5
        time.sleep(1.5)   # the summary line, written by a timer on the server's event loop
        lines = _lines(caplog)
    busy = [s for s in lines if "-> 503" in s]
    assert len(busy) <= 2 + burst_s / 1.0, busy   # was 60 lines: one per refusal
    assert busy[0] == "POST /v1/decode -> 503 busy: 2 decodes are running; retry shortly"
    assert _refusals_counted(lines) == 60, busy   # none uncounted
    assert sum("-> 415" in s and "junk.png" in s for s in lines) == 5   # other errors: one line each
