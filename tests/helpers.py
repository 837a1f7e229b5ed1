"""Shared test helpers."""
import subprocess
import sys


def run_cli(*args, timeout: int = 600, cwd=None):
    """`python -m snapshot3d ARGS` in a subprocess (in folder `cwd`)."""
    return subprocess.run([sys.executable, "-m", "snapshot3d", *args], capture_output=True, text=True, timeout=timeout,
                          cwd=cwd)


def assert_one_line_error(proc, match: str) -> None:
    """A user's mistake: non-zero exit, one line on stderr naming the cause, no traceback."""
    assert proc.returncode != 0
    err = proc.stderr.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert match in err, err
