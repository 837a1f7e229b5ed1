"""A command's `--report FILE`: a JSON document written atomically (no partial file ever stands at FILE)."""
from __future__ import annotations

import json
from pathlib import Path

__all__ = ["write_json"]


def write_json(path, doc: dict) -> None:
    """Write `doc` as indented JSON to `path` (nothing when `path` is empty or None)."""
    if not path:
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(json.dumps(doc, indent=2) + "\n")
    tmp.replace(path)
