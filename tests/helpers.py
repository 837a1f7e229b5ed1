"""Shared test helpers."""
import struct
import subprocess
import sys
import zlib


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


def bomb_png(path, n=20000):
    """A real 20000x20000 all-black PNG (~400 KB): the zeros are compressed row by row."""
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
    co = zlib.compressobj(1)
    row = b"\0" * (n + 1)
    idat = b"".join(co.compress(row) for _ in range(n)) + co.flush()
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", n, n, 8, 0, 0, 0, 0))
                     + chunk(b"IDAT", idat) + chunk(b"IEND", b""))
