"""`--budget auto` selection and marching-cubes meshing on known inputs."""
from dataclasses import replace

import numpy as np
import pytest

from snapshot3d.errors import UserError
from snapshot3d.meshing import density_to_mesh, unit_grid
from snapshot3d.train.field.budget import choose_rung, codec_psnr, expected_e2e
from snapshot3d.train.field.config import LADDER, LADDER_PRINT


def test_choose_smallest_rung_within_half_a_db():
    rungs = [{"scene_kb": 147, "field_psnr": 33.0}, {"scene_kb": 98, "field_psnr": 32.7},
             {"scene_kb": 55, "field_psnr": 32.4}, {"scene_kb": 12, "field_psnr": 29.0}]
    assert choose_rung(rungs) == 1  # 32.4 is 0.6 dB below the best
    assert choose_rung(rungs, tolerance_db=0.7) == 2
    rungs[3]["field_psnr"] = 33.5  # the smallest is also the best
    assert choose_rung(rungs) == 3


def test_a_medium_chooses_by_expected_e2e():
    """Through a lossy medium the field's error and the codec's add: a bigger field can lose to a smaller one."""
    assert expected_e2e(30.0, 30.0) == pytest.approx(26.99, abs=0.01)
    assert expected_e2e(40.0, 80.0) == pytest.approx(40.0, abs=1e-3)
    rungs = [{"scene_kb": 98, "field_psnr": 35.6, "codec_psnr": 18.0}, {"scene_kb": 12, "field_psnr": 31.2, "codec_psnr": 26.0},
             {"scene_kb": 3, "field_psnr": 27.6, "codec_psnr": 26.5}]
    for r in rungs:
        r["e2e_expected"] = expected_e2e(r["field_psnr"], r["codec_psnr"])
    assert choose_rung(rungs) == 0 and choose_rung(rungs, key="e2e_expected") == 1


def test_print_curve_ships_and_falls_with_payload():
    """The shipped print curve (bench codec --medium print, measured): the largest payload of the ladder
    restores worst, and every rung reads a measured, plausible value."""
    sizes = sorted({3 * c * r * r for r, c in LADDER_PRINT})
    db = [codec_psnr("print", v) for v in sizes]
    assert db[-1] == min(db) and db[0] - db[-1] > 2.0 and all(15 < v < 45 for v in db), db
    with pytest.raises(UserError, match="no codec curve for medium 'paper'"):
        codec_psnr("paper", 1000)


def test_ladder_stays_within_the_papers_budget():
    assert all(3 * c * r * r <= 160_000 for r, c in LADDER)
    assert len(set(LADDER)) == len(LADDER) >= 4


def test_marching_cubes_recovers_a_sphere():
    g = 48
    pts = unit_grid(g)
    r = np.linalg.norm(pts, axis=1)
    density = np.where(r < 0.5, 100.0, 0.0).reshape(g, g, g)
    box = np.array([[0.0, 0.0, 0.0], [2.0, 4.0, 2.0]])  # world box: the mesh is scaled into it
    mesh = density_to_mesh(density, 50.0, box, lambda p: np.tile([1.0, 0.0, 0.0], (len(p), 1)))
    centre = mesh.vertices.mean(0)
    np.testing.assert_allclose(centre, [1.0, 2.0, 1.0], atol=0.03)
    radii = np.abs(mesh.vertices - centre) / (box[1] - box[0]) * 2  # back in unit coordinates
    assert abs(np.median(np.linalg.norm(radii, axis=1)) - 0.5) < 0.03
    assert mesh.is_watertight and mesh.volume > 0  # outward normals
    assert np.all(mesh.visual.vertex_colors[:, :3] == [255, 0, 0])


def test_empty_field_has_no_mesh():
    with pytest.raises(UserError, match="no surface"):
        density_to_mesh(np.zeros((8, 8, 8)), 1.0, np.array([[0, 0, 0], [1, 1, 1.0]]), lambda p: p)


def test_the_print_ladder_fits_its_chosen_rung_again_from_scratch_and_keeps_the_better():
    """A print ladder's chosen rung, fine-tuned from the largest rung, is fitted again from scratch; the fit kept is
    the one the print channel's model expects better, and the rung says so. Without a medium there is no refit."""
    from snapshot3d.builtin import builtin_scene
    from snapshot3d.train.field.budget import fit_ladder
    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.decoder import load_decoder

    posed = builtin_scene("procedural", n_train=12, n_test=3, size=32, seed=1)
    cfg = FitConfig(steps=30, batch_rays=512, occ_warmup=10, ending="plain")
    lines = []
    chosen, rungs = fit_ladder(posed, load_decoder(), cfg, ladder=[(24, 4), (16, 4)], tolerance_db=99.0,
                               log=lines.append, medium="print")
    rung = rungs[chosen]
    assert chosen == 1 and "refit" not in rungs[0] and sum("R=16 C=4 again from scratch" in s for s in lines) == 1
    refit = rung["refit"]
    assert rung["fit_seconds"] >= refit["fit_seconds"] > 0
    if refit["kept"]:
        assert rung["e2e_expected"] == refit["e2e_expected"] and rung["field_psnr"] == refit["field_psnr"]
    else:
        assert rung["e2e_expected"] > refit["e2e_expected"]
    chosen, rungs = fit_ladder(posed, load_decoder(), cfg, ladder=[(24, 4), (16, 4)], tolerance_db=99.0, log=len)
    assert chosen == 1 and not any("refit" in r for r in rungs)


def test_the_refit_is_kept_by_the_model_or_for_the_object_alone_by_its_floaters():
    """--refit auto keeps the chosen rung's fit from scratch where the model expects it no worse, and for the
    object alone (background model and --object-steps) also where it leaves less opacity outside the largest
    rung's outline; model: by the model only; always: always."""
    from snapshot3d.train.field.budget import refit_kept
    from snapshot3d.train.field.config import FitConfig, check_fit_config

    white, alone = FitConfig(background="white"), FitConfig(background="outer")
    fewer, more = {"tuned": 0.02, "again": 0.01}, {"tuned": 0.01, "again": 0.03}
    kept = {(refit, bg.background, again, f is fewer): refit_kept(replace(bg, refit=refit), again, 19.0, f)
            for refit in ("auto", "model", "always") for bg in (white, alone) for again in (18.5, 19.0)
            for f in (fewer, more)}
    lost = [k for k, v in kept.items() if not v]
    assert lost == [("auto", "white", 18.5, True), ("auto", "white", 18.5, False), ("auto", "outer", 18.5, False),
                    ("model", "white", 18.5, True), ("model", "white", 18.5, False),
                    ("model", "outer", 18.5, True), ("model", "outer", 18.5, False)]
    assert not refit_kept(alone, 18.5, 19.0, None)   # no opacity measured (the room kept): by the model
    with pytest.raises(UserError, match="--refit must be auto, model or always, not 'yes'"):
        check_fit_config(FitConfig(refit="yes"))


def test_the_refit_s_floaters_are_both_rungs_opacity_outside_the_largest_rung_s_outline():
    """refit_floaters: opacity within 2 px of the largest rung's outline is forgiven, farther out it counts, and a
    fit that does not end on the object alone measures nothing."""
    from snapshot3d.train.field.budget import refit_floaters
    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.object_score import opacity_outside

    masks = np.zeros((1, 20, 20), bool)
    masks[0, 5:15, 5:15] = True
    inside = masks.astype(np.float32)
    far, near = inside.copy(), inside.copy()
    far[0, 0, 0] = 0.5           # 5 px from the outline
    near[0, 16, 10] = 0.5        # 2 px from it
    rungs = [{"_opacity": inside, "_masks": masks}, {"_opacity": far}, {"_opacity": near}]
    got = refit_floaters(FitConfig(background="outer"), *rungs)
    assert got == {"tuned": round(0.5 / 100.5, 4), "again": 0.0}
    assert refit_floaters(FitConfig(background="white"), *rungs) is None
    assert refit_floaters(FitConfig(background="outer", object_steps=0.0), *rungs) is None
    assert opacity_outside(near, masks, grow=0) == pytest.approx(0.5 / 100.5, rel=1e-6, abs=1e-9)
    assert opacity_outside(np.zeros_like(inside), masks) == 0.0
