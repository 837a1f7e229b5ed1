"""`bench print-ablation`'s premises: a variant changes only its knobs, its photo keeps every other random draw,
and the oracle flat field undoes a light the blank sheet shows."""
import numpy as np
import pytest


def test_each_variant_sets_only_its_knobs():
    from bench.print_ablation import VARIANTS, variant_preset
    from snapshot3d.scanner.presets import get_preset
    base = get_preset("moderate").as_dict()
    for name, knobs in VARIANTS.items():
        got = variant_preset("moderate", name).as_dict()
        changed = {k for k in base if got[k] != base[k]}
        assert changed == {k for k, v in knobs.items() if base[k] != v}, name
    assert {"tilt_deg", "glare", "jpeg_quality", "defocus_px"} <= set(VARIANTS["print-alone"])
    assert "halftone" not in VARIANTS["print-alone"]   # the print keeps all of its own damage
    assert {"halftone", "tone_gamma", "paper_texture"} <= set(VARIANTS["camera-alone"])
    assert not set(VARIANTS["camera-alone"]) & set(VARIANTS["print-alone"])   # and the camera all of its own


def test_a_variants_photo_keeps_the_presets_other_draws():
    """Setting glare to 0 leaves the pose, the light's other parts, the blur and the noise of the photo as drawn."""
    from bench.print_ablation import variant_preset
    from snapshot3d.scanner import layout
    from snapshot3d.scanner.simulate import simulate
    w, h = layout.sheet_size()
    sheet = np.full((h, w, 3), 200, np.uint8)   # a blank sheet at one pixel per layout unit
    _, _, base = simulate(sheet, variant_preset("moderate", "preset"), 3, print_seed=9)
    _, _, lit = simulate(sheet, variant_preset("moderate", "no-glare"), 3, print_seed=9)
    assert lit["pose"] == base["pose"] and lit["corners"] == base["corners"]
    for k, v in base["sampled"].items():
        if k == "glare":
            assert lit["sampled"][k] == 0.0 < v
        elif k != "jpeg_quality":
            assert lit["sampled"][k] == v, k


def test_the_oracle_flat_field_undoes_the_blank_sheets_light(rng):
    from bench.print_ablation import flat_field_fix
    from snapshot3d.scanner.printing import linear_to_srgb_u8, srgb_to_linear
    pic = srgb_to_linear(rng.integers(40, 220, (380, 380, 3)).astype(np.uint8))
    light = np.linspace(0.4, 1.0, 380, dtype=np.float32)[None, :, None] * np.ones((380, 1, 3), np.float32)
    blank = linear_to_srgb_u8(np.full_like(pic, 0.5) * light)
    lit = linear_to_srgb_u8(pic * light)
    got = flat_field_fix(lit, blank).astype(np.float64)
    ref = linear_to_srgb_u8(pic * np.median(light)).astype(np.float64)   # relative to the blank's median light
    inner = (slice(20, -20), slice(20, -20))   # the smoothing's edge
    assert np.abs(got - ref)[inner].mean() < 1.5
    assert np.abs(lit.astype(np.float64) - ref)[inner].mean() > 8


def test_a_pair_counts_only_where_the_variant_kept_the_presets_later_draws():
    """A changed pose can take the placement more tries and redraw the light, blur and noise after it: such a photo
    is no pair for the paired gain, though it counts in the medians."""
    from bench.print_ablation import _pairs, _summary
    rows = [{"variant": v, "host": "h", "seed": s, "true_albedo": a, "restore_psnr": p, "e2e_psnr": p - 3}
            for v, s, a, p in (("preset", 0, 0.5, 20.0), ("preset", 1, 0.6, 22.0),
                               ("no-tilt-or-lens", 0, 0.5, 21.0), ("no-tilt-or-lens", 1, 0.7, 30.0))]
    assert [(b["seed"], r["seed"]) for b, r in _pairs(rows, "no-tilt-or-lens")] == [(0, 0)]
    s = _summary(rows)["no-tilt-or-lens"]
    assert s["pairs"] == 1 and s["photos"] == 2 and s["restore_psnr_wins"] == "1/1"
    assert s["restore_psnr_gain"] == pytest.approx(1.0, rel=1e-9, abs=1e-9)
    assert s["restore_psnr_median_diff"] == pytest.approx(25.5 - 21.0, rel=1e-9, abs=1e-9)
