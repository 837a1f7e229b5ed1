"""Every committed benchmark result records the run that wrote it (bench/README.md, "Methodology"): its
date, commit, core count and library versions, so that a figure can be traced to the machine that made it."""
import json
import re
from pathlib import Path

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "bench" / "results"
FILES = sorted(p for p in RESULTS.rglob("*.json") if "quick" not in p.relative_to(RESULTS).parts[:-1])  # not smoke runs


def test_there_are_results():
    assert len(FILES) >= 15, [p.name for p in FILES]


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(RESULTS)))
def test_results_record_their_run(path):
    meta = json.loads(path.read_text()).get("meta")
    assert isinstance(meta, dict), f"{path.relative_to(RESULTS)} has no 'meta' entry"
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", meta.get("date", "")), meta.get("date")
    assert re.fullmatch(r"[0-9a-f]{7,40}(\+dirty)?|unknown", meta.get("commit", "")), meta.get("commit")
    backfilled = bool(meta.get("backfilled"))  # written before runs recorded it: the file's last commit
    assert isinstance(meta.get("cores"), int) and meta["cores"] >= 1 or backfilled and meta.get("cores") == \
        "not recorded", meta.get("cores")
    versions = meta.get("versions")
    assert versions == "not recorded" and backfilled or \
        isinstance(versions, dict) and {"python", "numpy", "opencv", "onnxruntime"} <= set(versions), versions


def test_run_metadata_has_every_field():
    from snapshot3d.bench.common import run_metadata

    meta = run_metadata()
    assert {"date", "commit", "cores", "cpu", "versions"} <= set(meta)
    assert isinstance(meta["cpu"], str) and meta["cpu"], meta["cpu"]
    assert {"python", "numpy", "opencv", "onnxruntime"} <= set(meta["versions"])


def test_decode_profile_writes_stage_shares(tmp_path):
    """`bench decode --profile`: each stage's median and share of the decode, and cProfile's listing."""
    from snapshot3d.bench.decode_profile import STAGES, profile_decode

    doc = profile_decode(tmp_path, repeats=1, top=5, cold=1)
    # each share is rounded to 3 decimals, so their sum may exceed 1 by half a unit per stage
    assert set(doc["stages_share"]) == set(STAGES)
    assert 0.8 <= sum(doc["stages_share"].values()) <= 1.0 + 0.0005 * len(STAGES)
    assert doc["decode_ms_median"] > 0 and 0 < doc["first_view_ms_median"] <= doc["decode_ms_median"]
    assert len(doc["top_by_tottime"]) == 5 and json.loads((tmp_path / "decode_profile.json").read_text())["meta"]
    assert "cumulative" in (tmp_path / "decode_profile.txt").read_text()
    cold = doc["cold"]  # one decode in a fresh process, as a user's first
    assert set(cold["stages_ms"]) == set(STAGES) and 0 < cold["first_view_ms"] <= cold["decode_ms"]
    assert (tmp_path / "decode_profile.png").stat().st_size > 10_000
