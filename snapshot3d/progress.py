"""Progress bars for long work (DESIGN section 2): a tqdm bar with an ETA on stderr, shown only when
stderr is a terminal (set SNAPSHOT3D_PROGRESS=1 to force it, 0 to hide it)."""
from __future__ import annotations

import os
import sys

__all__ = ["progress"]


def _enabled() -> bool | None:
    flag = os.environ.get("SNAPSHOT3D_PROGRESS")
    if flag is not None:
        return flag not in ("", "0")
    return None  # tqdm decides: on for a terminal, off otherwise


def progress(total: int, desc: str, unit: str = "step"):
    """A bar over `total` units: `.update(n)`, `.set_postfix_str(s)`, `.close()` (also a context manager)."""
    from tqdm import tqdm

    on = _enabled()
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True, leave=False,
                disable=(not on) if on is not None else None, mininterval=0.5)
