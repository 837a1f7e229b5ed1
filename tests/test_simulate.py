"""The print-and-capture simulator: deterministic per seed, truth that matches the pixels, presets in range."""
import time

import cv2
import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.scanner import layout
from snapshot3d.scanner.detect import detect_markers
from snapshot3d.scanner.presets import PRESETS
from snapshot3d.scanner.qr import SheetMeta
from snapshot3d.scanner.sheet import render_sheet
from snapshot3d.scanner.simulate import blur_kernel, simulate


@pytest.fixture(scope="module")
def sheet():
    rng = np.random.default_rng(3)
    snap = cv2.resize((rng.random((48, 48, 3)) * 255).astype(np.uint8), (formats.SNAPSHOT_SIZE,) * 2,
                      interpolation=cv2.INTER_CUBIC)
    return render_sheet(snap, SheetMeta(), 2)


def _decode(data):
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)


def test_none_is_the_sheet_itself(sheet):
    data, ext, truth = simulate(sheet, "none", 0)
    assert ext == ".png"
    np.testing.assert_array_equal(cv2.cvtColor(_decode(data), cv2.COLOR_BGR2RGB), sheet)
    x0, y0 = formats.SHEET_BOX[:2]
    assert truth["corners"][0] == [-x0 * 2 - 0.5, -y0 * 2 - 0.5]


def test_deterministic_per_seed_and_fast(sheet):
    t = time.perf_counter()
    a = simulate(sheet, "moderate", 5)
    elapsed = time.perf_counter() - t
    b = simulate(sheet, "moderate", 5)
    c = simulate(sheet, "moderate", 6)
    assert a[0] == b[0] and a[2] == b[2]
    assert a[0] != c[0]
    assert elapsed < 6.0, f"a 12 MP simulation took {elapsed:.1f} s"  # ~1-2 s alone; the CPU is shared


@pytest.mark.parametrize("severity,seed", [("mild", 0), ("moderate", 1)])
def test_truth_matches_the_rendered_photo(sheet, severity, seed):
    """Markers found independently in the photo lie where the truth's geometry puts them."""
    data, ext, truth = simulate(sheet, severity, seed)
    img = _decode(data)
    W, H = PRESETS[severity].frame
    assert img.shape == (H, W, 3) and ext == ".jpg"
    p = truth["pose"]
    assert 0.0 <= p["tilt_deg"] <= PRESETS[severity].tilt_deg[1]
    assert 0.02 < p["coverage"] <= PRESETS[severity].coverage[1] + 0.01
    corners = np.array(truth["corners"])
    assert corners.shape == (4, 2) and np.all(corners >= 0) and np.all(corners < (W, H))
    from snapshot3d.scanner.camera import Camera, apply_h, distort
    cam = Camera(**{k: v for k, v in p["camera"].items() if k not in ("width", "height")},
                 width=W, height=H)
    Hm = np.array(p["H_layout_to_ideal_px"])
    np.testing.assert_allclose(distort(apply_h(Hm, layout.snapshot_corners()), cam), corners, atol=1e-6)
    ids, found = detect_markers(img)
    ref = layout.marker_corners()
    assert set(ids.tolist()) >= {0, 1, 2, 3}
    for i, q in zip(ids.tolist(), found):
        if i in ref:
            err = np.linalg.norm(q - distort(apply_h(Hm, ref[i]), cam), axis=1)
            assert err.max() < 2.0, (i, err)


def test_presets_get_harder():
    keys = ["tilt_deg", "k1", "defocus_px", "motion_px", "noise_shot", "noise_read", "glare", "shadow"]
    for k in keys:
        hi = [abs(getattr(PRESETS[s], k)[1]) for s in ("mild", "moderate", "severe")]
        assert hi == sorted(hi), k
    assert PRESETS["severe"].tilt_deg[1] == 60.0
    assert PRESETS["mild"].jpeg_quality[0] > PRESETS["severe"].jpeg_quality[1]


def test_blur_kernel():
    k = blur_kernel(2.0, 6.0, 0.3)
    assert abs(k.sum() - 1) < 1e-5 and k.shape[0] == k.shape[1] and k.shape[0] % 2 == 1
    assert k[k.shape[0] // 2, k.shape[0] // 2] == pytest.approx(k.max(), rel=0.5)


def test_severity_names_have_one_source():
    """The presets, the command line and the benches name the severities of `formats.SEVERITIES`."""
    from snapshot3d.bench.common import SEVERITIES as BENCH
    from snapshot3d.cli import build_parser
    from snapshot3d.scanner.presets import SEVERITIES
    assert tuple(PRESETS) == SEVERITIES == BENCH == formats.SEVERITIES
    simulate = build_parser()._subparsers._group_actions[0].choices["simulate"]
    assert next(a for a in simulate._actions if a.dest == "severity").choices == formats.SEVERITIES
