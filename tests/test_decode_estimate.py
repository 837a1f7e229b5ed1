"""The decode report's quality estimate is built once (`viewer.decode`): with its views term after the views,
or without it for `decode_scene(estimate=False)`; its contents are what the two builds made before (the
views term's build read the first build's pilot_psnr_db and plane_rmse_expected)."""
from importlib import resources
from pathlib import Path

import pytest

from snapshot3d.viewer import decode
from snapshot3d.viewer.quality import quality_estimate

PHOTO = Path(str(resources.files("snapshot3d") / "assets" / "example-photo.jpg"))   # a print codec
FILE_SNAPSHOT = Path(__file__).parent / "data" / "spot-snapshot.png"                # the file medium


@pytest.fixture
def calls(monkeypatch):
    seen = []

    def counted(*args):
        seen.append(args)
        return quality_estimate(*args)
    monkeypatch.setattr(decode, "quality_estimate", counted)
    return seen


def _as_before(report: dict, views_psnr) -> dict:
    """The old second build: from the report's own pilot and plane RMS error, and the views term."""
    q = report["quality_estimate"]
    return quality_estimate(report["codec"], q["pilot_psnr_db"], q["plane_rmse_expected"], views_psnr)


def test_a_photo_of_a_print_builds_its_estimate_once(calls):
    rep = decode.decode_photo(PHOTO, views=2, size=48).report
    assert len(calls) == 1
    codec, pilot, rmse, views = calls[0]
    assert rep["medium"] == "print" and views is not None and rep["quality_estimate"]["views_psnr_expected_db"]
    assert rep["quality_estimate"] == _as_before(rep, views)
    assert rep["quality_estimate"]["pilot_psnr_db"] == pilot and 10 < pilot < 60
    assert 15 < rep["quality_estimate"]["restore_psnr_expected_db"] < 40 and "quality" in rep["timings_ms"]


def test_a_snapshot_file_and_no_views_term_build_it_once_too(calls):
    rep = decode.decode_scene(FILE_SNAPSHOT).report
    assert len(calls) == 1 and rep["quality_estimate"] == _as_before(rep, calls[0][3])
    assert rep["quality_estimate"]["basis"].startswith("none: a snapshot file")
    rep = decode.decode_scene(PHOTO, estimate=False).report
    assert len(calls) == 2 and calls[1][3] is None
    assert rep["quality_estimate"] == _as_before(rep, None) and rep["quality_estimate"]["views_psnr_expected_db"] is None
    assert rep["channel"] is not None and "quality" not in rep["timings_ms"]
