"""`bench capture-summary`: issue 40's targets by the medians over fit seeds, read from capture-background files."""
import json

import pytest
from helpers import assert_one_line_error, run_cli


def _near(value):
    """A median or gap as the summary rounds it: within its rounding, relative and absolute."""
    return pytest.approx(value, rel=1e-6, abs=1e-6)


def _file(path, seed, arc, rows):
    path.write_text(json.dumps({"meta": {}, "capture": {"seed": seed, "arc_deg": arc}, "rows": rows}))
    return path


def _row(mode, fit_seed, psnr, outside, weight=None, **more):
    row = {"mesh": "spot", "mode": mode, "fit_seed": fit_seed, "object_psnr": psnr, "opacity_outside_2px": outside,
           **more}
    return row if weight is None else {**row, "seen_ground_weight": weight}


@pytest.fixture
def results(tmp_path):
    a = _file(tmp_path / "a.json", 0, 120.0, [_row("masked", 0, 25.0, 0.0), _row("outer", 0, 24.0, 0.03),
                                              _row("outer-seen-03", 0, 22.0, 0.01)])   # before the key was kept
    b = _file(tmp_path / "b.json", 0, 120.0, [_row("outer", 0, 24.0, 0.03, 0.0),      # the same fit again
                                              _row("outer-noseen", 10, 23.0, 0.01, 0.0),
                                              _row("outer-noseen", 11, 25.0, 0.02, 0.0),
                                              _row("outer", 10, 23.9, 0.005, 0.3), _row("outer", 11, 23.0, 0.02, 0.3),
                                              # the same fit seeds with the object's cells spared: apart
                                              _row("outer", 10, 24.6, 0.01, 0.3, seen_ground_spare=True,
                                                   object_ring_psnr=20.0, object_inner_psnr=27.0)])
    walk = _file(tmp_path / "walk.json", 0, 720.0, [_row("outer", 0, 26.0, 0.008, 0.0), _row("white", 0, 9.0, 0.5),
                                                   _row("outer-ground256", 0, 27.0, 0.001, 0.0)])
    return [a, b, walk]


def test_the_medians_over_fit_seeds_meet_the_targets_or_not(results):
    from snapshot3d.bench.capture_summary import _totals, fit_rows, summary_rows
    fits = fit_rows(results)
    assert len(fits) == 10   # the repeated fit counts once, the white one not at all
    rows = {(r["arc_deg"], r["seen_ground_weight"]): r for r in summary_rows(fits) if r["variant"] == "outer"}
    plain, seen, walk = rows[(120.0, 0.0)], rows[(120.0, 0.3)], rows[(720.0, 0.0)]
    assert plain["fits"] == 3 and plain["object_psnr"] == _near(24.0) and plain["outside"] == _near(0.02)
    assert plain["gap_db"] == _near(-1.0) and plain["within_gap"] and plain["within_outside"]
    assert seen["fits"] == 3 and seen["fit_seeds"] == "0;10;11" and seen["object_psnr"] == _near(23.0)
    assert seen["gap_db"] == _near(-2.0) and not seen["within_gap"] and seen["outside"] == _near(0.01)
    assert walk["gap_db"] is None and walk["within_gap"] is None   # no masked fit of that capture
    assert walk["fits"] == 1 and walk["object_psnr"] == _near(26.0)   # the white fit left out, another variant apart
    other = [r for r in summary_rows(fits) if r["variant"] == "outer-ground256"]
    assert len(other) == 1 and other[0]["object_psnr"] == _near(27.0)
    spare = [r for r in summary_rows(fits) if r["variant"] == "outer-spare"]
    assert len(spare) == 1 and spare[0]["fits"] == 1 and spare[0]["gap_db"] == _near(-0.4)
    # the outline's split where the rows carry it, else None (the masked fit here predates it)
    assert spare[0]["ring_psnr"] == _near(20.0) and spare[0]["inner_psnr"] == _near(27.0)
    assert spare[0]["ring_masked_psnr"] is None and seen["ring_psnr"] is None
    totals = _totals(list(rows.values()))
    assert totals["0"] == {"captures": 2, "within_gap": 1, "within_outside": 2, "both": 1, "clean_captures": 0,
                           "within_clean_gap": 0, "both_clean": 0, "median_fits": 2.0}
    assert totals["0.3"]["both"] == 0


def test_the_command_writes_its_files_and_refuses_what_is_not_a_result(results, tmp_path):
    out = tmp_path / "out"
    proc = run_cli("bench", "capture-summary", *map(str, results), "--out", str(out), "--name", "s")
    assert proc.returncode == 0, proc.stderr
    assert "spot seed 0 120° weight 0: 24.00 dB, gap -1.00, 2.00% outside (3 fits)" in proc.stdout
    assert "spot seed 0 720° weight 0 (outer-ground256): 27.00 dB, 0.10% outside (1 fit)" in proc.stdout
    assert "0.3 (outer-spare): 24.60 dB, gap -0.40 (outline 20.00, inside 27.00), 1.00% outside" in proc.stdout
    assert {p.name for p in out.iterdir()} == {"s.json", "s.csv", "s.png"}
    assert json.loads((out / "s.json").read_text())["totals"]["0.3"]["captures"] == 1
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    proc = run_cli("bench", "capture-summary", str(bad), "--out", str(tmp_path / "none"))
    assert_one_line_error(proc, "bad.json: not a bench capture-background result")
    proc = run_cli("bench", "capture-summary", str(tmp_path / "absent.json"), "--out", str(tmp_path / "none"))
    assert_one_line_error(proc, "absent.json: no such results file")
    assert not (tmp_path / "none").exists()


def test_the_gap_against_the_object_over_white_is_counted_apart(tmp_path):
    """Fits scored against the object alone over white too (object_clean_psnr) get their own gap and target; the
    photos' gap is left as it was."""
    from snapshot3d.bench.capture_summary import _totals, fit_rows, summary_rows
    clean = {"masked": 25.0, 10: 24.0, 11: 23.0}
    rows = [_row("masked", 0, 24.0, 0.0, object_clean_psnr=clean["masked"]),
            _row("outer", 10, 21.0, 0.01, 0.3, object_clean_psnr=clean[10]),
            _row("outer", 11, 22.0, 0.025, 0.3, object_clean_psnr=clean[11])]
    summary = summary_rows(fit_rows([_file(tmp_path / "c.json", 1, 120.0, rows)]))
    (row,) = [r for r in summary if r["variant"] == "outer"]
    assert row["gap_db"] == _near(-2.5) and not row["within_gap"]
    assert row["clean_psnr"] == _near(23.5) and row["clean_masked_psnr"] == _near(25.0)
    assert row["clean_gap_db"] == _near(-1.5) and row["within_clean_gap"] and row["within_outside"]
    assert _totals([row])["0.3"] == {"captures": 1, "within_gap": 0, "within_outside": 1, "both": 0,
                                     "clean_captures": 1, "within_clean_gap": 1, "both_clean": 1, "median_fits": 2.0}


def test_the_edge_opacity_by_what_lies_behind_is_a_median_beside_the_bound(tmp_path):
    """Fits that carry score_object's edge split get its medians, and the masked fits' beside them; rows without it
    get None."""
    from snapshot3d.bench.capture_summary import fit_rows, summary_rows
    edge = {"masked": (0.1, 0.05, 0.6), 10: (0.4, 0.2, 0.7), 11: (0.3, 0.1, 0.9), 12: (0.2, 0.3, 0.5)}
    rows = [_row("masked", 0, 24.0, 0.0, **dict(zip(("edge_opacity_near", "edge_opacity_far",
                                                     "edge_near_share"), edge["masked"])))]
    rows += [_row("outer", s, 22.0, 0.01, 0.3, **dict(zip(("edge_opacity_near", "edge_opacity_far",
                                                          "edge_near_share"), edge[s]))) for s in (10, 11, 12)]
    rows.append(_row("outer", 1, 22.0, 0.01, 0.0))   # another setting, written before the split
    summary = {r["seen_ground_weight"]: r for r in summary_rows(fit_rows([_file(tmp_path / "e.json", 0, 120.0, rows)]))}
    row = summary[0.3]
    assert row["edge_opacity_near"] == _near(0.3) and row["edge_opacity_far"] == _near(0.2)
    assert row["edge_near_share"] == _near(0.7)
    assert row["edge_opacity_near_masked"] == _near(0.1) and row["edge_opacity_far_masked"] == _near(0.05)
    assert summary[0.0]["edge_opacity_near"] is None and summary[0.0]["edge_opacity_near_masked"] == _near(0.1)
