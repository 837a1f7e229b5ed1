"""Benchmark reports: rows as CSV and a summary as JSON that names the command and the core count."""
from __future__ import annotations

import csv
import json
import os
import sys
from pathlib import Path

__all__ = ["write_report"]


def write_report(out: Path, stem: str, rows: list[dict], doc: dict) -> dict:
    """Write out/stem.csv (rows; columns of the first row) and out/stem.json (`doc` after "command" and
    "cores"); returns the JSON document."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / f"{stem}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    doc = {"command": "snapshot3d " + " ".join(sys.argv[1:]), "cores": os.cpu_count(), **doc}
    (out / f"{stem}.json").write_text(json.dumps(doc, indent=2) + "\n")
    return doc
