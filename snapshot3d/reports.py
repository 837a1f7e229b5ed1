"""A command's `--report FILE`: a JSON document written atomically (no partial file ever stands at FILE)."""
from __future__ import annotations

import json
from pathlib import Path

from .errors import UserError

__all__ = ["write_json"]


def write_json(path, doc: dict) -> None:
    """Write `doc` as indented JSON to `path` (nothing when `path` is empty or None)."""
    if not path:
        return
    path = Path(path)
    text = json.dumps(doc, indent=2) + "\n"
    tmp = path.with_name(path.name + ".partial")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(text)
        tmp.replace(path)
    except OSError as e:
        if tmp.parent.is_dir():
            tmp.unlink(missing_ok=True)
        raise UserError(f"cannot write the report {path}: {e.strerror or type(e).__name__}") from None
