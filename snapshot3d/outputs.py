"""An output folder written as a whole: everything goes into a hidden sibling folder first and is moved
into place at the end, so that an interrupted or failed command never leaves a half-written folder."""
from __future__ import annotations

import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

from .errors import UserError

__all__ = ["staged_folder"]


def _publish(tmp: Path, out: Path) -> None:
    if out.exists():
        if not out.is_dir():
            raise UserError(f"{out} exists and is not a folder")
        old = out.with_name(f".{out.name}.old")
        shutil.rmtree(old, ignore_errors=True)
        out.rename(old)
        tmp.rename(out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(out)


@contextmanager
def staged_folder(out):
    """`with staged_folder(out) as tmp:` write into `tmp`; on success it replaces `out` (a folder)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise UserError(f"{out} exists and is not a folder")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    except OSError as e:
        raise UserError(f"cannot write into {out.parent}: {e.strerror or type(e).__name__}") from None
    try:
        yield tmp
        _publish(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
