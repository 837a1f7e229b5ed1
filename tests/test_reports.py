"""Benchmark reports name their command and core count beside the rows."""
import csv
import json
import os

import numpy as np

from snapshot3d.bench.common import write_report


def test_write_report_csv_and_json(tmp_path):
    rows = [{"severity": "mild", "restore_psnr": 17.5}, {"severity": "moderate", "restore_psnr": 16.25}]
    doc = write_report(tmp_path / "r", "x", rows, {"summary": {"mild": 17.5}})
    back = list(csv.DictReader(open(tmp_path / "r" / "x.csv")))
    assert [r["severity"] for r in back] == ["mild", "moderate"] and float(back[1]["restore_psnr"]) == 16.25
    saved = json.loads((tmp_path / "r" / "x.json").read_text())
    assert saved == doc and saved["cores"] == os.cpu_count() and saved["command"].startswith("snapshot3d")
    assert saved["summary"] == {"mild": 17.5}


def test_row_blocks_resume_after_a_kill(tmp_path):
    from snapshot3d.bench.common import RowBlocks

    calls = []

    def block(name, value):
        calls.append(name)
        return [{"name": name, "v": np.float32(value)}]

    path = tmp_path / "run.partial.jsonl"
    first = RowBlocks(path, {"seeds": 6})
    assert first.rows("a", lambda: block("a", 1.5)) == [{"name": "a", "v": 1.5}]
    first.rows("b", lambda: block("b", 2.0))
    with open(path, "a") as f:
        f.write('{"key": "c", "rows": [{"na')  # the line a kill cut
    again = RowBlocks(path, {"seeds": 6})
    assert again.rows("a", lambda: block("a", 9)) == [{"name": "a", "v": 1.5}]
    assert again.rows("c", lambda: block("c", 3)) == [{"name": "c", "v": 3.0}]
    assert calls == ["a", "b", "c"]
    assert [json.loads(x)["key"] for x in path.read_text().splitlines()[1:]] == ["a", "b", "c"]
    other = RowBlocks(path, {"seeds": 2})  # another run's settings: nothing is reused
    other.rows("a", lambda: block("a", 4))
    assert calls == ["a", "b", "c", "a"]
    other.finish()
    assert not path.exists()
