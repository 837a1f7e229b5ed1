"""Running one fuzz input and naming its outcome (`bench fuzz`).

Outcomes: ok; error (UserError, or exit 1 / 2 with one line on stderr); traceback (any other exception, or
a traceback on stderr); nonfinite (a success whose result holds NaN/inf or a degenerate box or orbit);
partial (a failed command left its output, or a .partial file); multiline (more than one line on stderr:
library warnings beside the error, or on a success); timeout. In process, stdout and stderr are captured
at the file-descriptor level (C libraries' warnings included) and memory is tracemalloc's peak; a
subprocess's peak is its VmHWM (/proc, polled while it runs)."""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

__all__ = ["READERS", "run_inprocess", "run_subprocess", "finite", "write_files"]


def _read_image(d: Path, arg: str):
    from snapshot3d.viewer.decode import read_input
    return read_input(d / arg)


def _read_snapshot(d: Path, arg: str):
    from snapshot3d.scanner.qr import check_codec
    from snapshot3d.scanner.snapfile import read_snapshot
    name, _, text = arg.partition("|")
    rgb, meta = read_snapshot(d / name, text or None)
    check_codec(meta)
    return rgb, meta


def _read_meta(d: Path, arg: str):
    """A metadata text as every carrier's reader parses it (ValueError is decode_payload's documented refusal)."""
    from snapshot3d.errors import UserError
    from snapshot3d.scanner.qr import check_codec, check_meta, decode_payload
    try:
        meta = decode_payload(arg)
    except ValueError as e:
        raise UserError(str(e)) from None
    check_meta(meta)
    check_codec(meta)
    return meta


def _read_s3d(d: Path, arg: str):
    from snapshot3d.scene import load_scene_file
    return load_scene_file(d / arg)


def _read_transforms(d: Path, arg: str):
    from snapshot3d.loaders import load_scene
    return load_scene(str(d / arg))


READERS = {"image": _read_image, "snapshot": _read_snapshot, "meta": _read_meta, "s3d": _read_s3d,
           "transforms": _read_transforms}


def finite(x, depth: int = 0) -> bool:
    """No NaN/inf anywhere in a result, and no degenerate box (x1 <= x0) or orbit (radius <= 0, fov out of
    (0, 180)) in a scene or metadata."""
    if depth > 6:
        return True
    if isinstance(x, float):
        return math.isfinite(x)
    if isinstance(x, np.ndarray):
        return not np.issubdtype(x.dtype, np.floating) or bool(np.isfinite(x).all())
    if isinstance(x, dict):
        return all(finite(v, depth + 1) for v in x.values())
    if isinstance(x, (list, tuple)):
        return all(finite(v, depth + 1) for v in x)
    box, orbit = getattr(x, "box", None), getattr(x, "orbit", None)
    if box is not None:
        b = np.asarray(box, np.float64).reshape(2, 3)
        if not (np.isfinite(b).all() and (b[1] > b[0]).all()):
            return False
    if orbit is not None:
        r, fov = (getattr(orbit, "radius", None), getattr(orbit, "fov_deg", None)) if not isinstance(orbit, tuple) \
            else (orbit[0], orbit[2])
        if not (math.isfinite(float(r)) and r > 0 and 0 < float(fov) < 180):
            return False
    if hasattr(x, "__dict__") and not isinstance(x, type):
        return all(finite(v, depth + 1) for k, v in vars(x).items() if not k.startswith("_"))
    return True


def write_files(d: Path, files: dict) -> None:
    for name, data in files.items():
        try:
            (d / name).write_bytes(data)
        except OSError:  # a name this file system refuses: the input tests the missing file instead
            pass


class _Captured:
    """fd 1 -> /dev/null, fd 2 -> a temporary file, for C libraries too; `.text` after exit."""

    def __enter__(self):
        sys.stdout.flush(), sys.stderr.flush()
        self.tmp = tempfile.TemporaryFile()
        self.null = os.open(os.devnull, os.O_WRONLY)
        self.saved = os.dup(1), os.dup(2)
        os.dup2(self.null, 1), os.dup2(self.tmp.fileno(), 2)
        return self

    def __exit__(self, *exc):
        sys.stdout.flush(), sys.stderr.flush()
        os.dup2(self.saved[0], 1), os.dup2(self.saved[1], 2)
        for fd in (*self.saved, self.null):
            os.close(fd)
        self.tmp.seek(0)
        self.text = self.tmp.read().decode("utf-8", "replace")
        self.tmp.close()


def _alarm(signum, frame):
    raise TimeoutError("fuzz input time limit")


def _stderr_lines(text: str, rc) -> list[str]:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if rc == 2:  # argparse: "usage: ..." (and its indented continuation) then one "error:" line
        lines = [ln for ln in lines if not ln.startswith("usage:") and not ln.startswith(" ")]
    return lines


def _output_nonfinite(d: Path, outputs) -> bool:
    from snapshot3d.scene import load_scene_file
    for name in outputs:
        p = d / name
        for f in ([p] if p.is_file() else sorted(p.rglob("*")) if p.is_dir() else []):
            if f.suffix == ".s3d" and not finite(load_scene_file(f)):
                return True
            if f.suffix == ".json":
                try:
                    json.loads(f.read_text(), parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
                except ValueError:
                    return True
    return False


def _classify_cli(rc, err: str, d: Path, outputs) -> tuple[str, str]:
    lines = _stderr_lines(err, rc)
    if "Traceback (most recent call last)" in err:
        return "traceback", (lines[-1] if lines else "")[:160]
    if rc == 0:
        if _output_nonfinite(d, outputs):
            return "nonfinite", "output holds NaN/inf or a degenerate scene"
        return ("multiline", " / ".join(lines)[:160]) if len(lines) > 1 else ("ok", "")
    left = [n for n in outputs if (d / n).exists()] + [p.name for p in d.rglob("*.partial")]
    if left:
        return "partial", f"left {left[:3]} after exit {rc}: {(lines or [''])[-1][:100]}"
    if len(lines) != 1:
        return "multiline", " / ".join(lines)[:160] or f"exit {rc} with nothing on stderr"
    return "error", lines[0][:160]


def run_inprocess(inp, root: Path, limit_s: float = 60.0) -> dict:
    """One input in this process: a reader, or `snapshot3d.cli.main(argv)`."""
    from snapshot3d.cli import main
    from snapshot3d.errors import UserError
    d = Path(tempfile.mkdtemp(dir=root))
    write_files(d, inp.files)
    argv = [a.replace("{d}", str(d)) for a in inp.argv] if inp.argv else None
    rc, exc, result = None, None, None
    tracemalloc.reset_peak()
    t0 = time.perf_counter()
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, limit_s)
    try:
        with _Captured() as cap:
            try:
                if argv is not None:
                    rc = main(argv)
                else:
                    result = READERS[inp.reader](d, inp.arg)
            except SystemExit as e:
                rc = e.code if isinstance(e.code, int) else 1
            except UserError as e:
                exc = e
            except BaseException as e:  # noqa: BLE001 - the fuzz records what escaped
                exc = e
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    secs = time.perf_counter() - t0
    peak_mb = tracemalloc.get_traced_memory()[1] / 1e6
    if isinstance(exc, TimeoutError) and "fuzz input time limit" in str(exc):
        outcome, detail = "timeout", f"over {limit_s:g} s"
    elif exc is not None and not isinstance(exc, UserError):
        tb = exc.__traceback__
        while tb is not None and tb.tb_next is not None:
            tb = tb.tb_next
        where = f"{Path(tb.tb_frame.f_code.co_filename).name}:{tb.tb_lineno}" if tb else "?"
        outcome, detail = "traceback", f"{type(exc).__name__} at {where}: {str(exc)[:100]}"
    elif argv is not None:
        outcome, detail = _classify_cli(rc, cap.text, d, inp.outputs)
    else:
        lines = _stderr_lines(cap.text, None)
        if exc is not None:
            msg = str(exc)
            outcome, detail = ("multiline", msg[:160]) if "\n" in msg.strip() or lines else ("error", msg[:160])
        elif not finite(result):
            outcome, detail = "nonfinite", "reader returned NaN/inf or a degenerate scene"
        else:
            outcome, detail = ("multiline", " / ".join(lines)[:160]) if lines else ("ok", "")
    _rmtree(d)
    return {"outcome": outcome, "detail": detail, "peak_mb": round(peak_mb, 1), "secs": round(secs, 3)}


def run_subprocess(inp, root: Path, limit_s: float = 180.0) -> dict:
    """One command line as a real `python -m snapshot3d` process: its stderr and its peak RSS."""
    d = Path(tempfile.mkdtemp(dir=root))
    write_files(d, inp.files)
    argv = [a.replace("{d}", str(d)) for a in inp.argv]
    env = dict(os.environ, SNAPSHOT3D_PROGRESS="0")
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        p = subprocess.Popen([sys.executable, "-m", "snapshot3d", *argv], stdout=subprocess.DEVNULL, stderr=err,
                             env=env)
        deadline, hwm_kb = time.monotonic() + limit_s, 0
        while True:  # VmHWM read while it runs (ru_maxrss of a forked child starts at this process's RSS)
            hwm_kb = max(hwm_kb, _vm_hwm_kb(p.pid))
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() > deadline:
                p.kill()
                pid, status, usage = os.wait4(p.pid, 0)
                break
            time.sleep(0.01)
        p.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        text = err.read().decode("utf-8", "replace")
    secs = time.perf_counter() - t0
    if secs > limit_s:
        outcome, detail = "timeout", f"over {limit_s:g} s"
    else:
        outcome, detail = _classify_cli(p.returncode, text, d, inp.outputs)
    _rmtree(d)
    return {"outcome": outcome, "detail": detail, "peak_mb": round(hwm_kb / 1024, 1), "secs": round(secs, 2)}


def _vm_hwm_kb(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except (OSError, ValueError):
        pass
    return 0


def _rmtree(d: Path) -> None:
    import shutil
    shutil.rmtree(d, ignore_errors=True)
