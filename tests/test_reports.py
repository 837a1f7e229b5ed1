"""Benchmark reports name their command and core count beside the rows."""
import csv
import json
import os

from snapshot3d.bench.common import write_report


def test_write_report_csv_and_json(tmp_path):
    rows = [{"severity": "mild", "restore_psnr": 17.5}, {"severity": "moderate", "restore_psnr": 16.25}]
    doc = write_report(tmp_path / "r", "x", rows, {"summary": {"mild": 17.5}})
    back = list(csv.DictReader(open(tmp_path / "r" / "x.csv")))
    assert [r["severity"] for r in back] == ["mild", "moderate"] and float(back[1]["restore_psnr"]) == 16.25
    saved = json.loads((tmp_path / "r" / "x.json").read_text())
    assert saved == doc and saved["cores"] == os.cpu_count() and saved["command"].startswith("snapshot3d")
    assert saved["summary"] == {"mild": 17.5}
