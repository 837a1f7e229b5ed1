"""`bench channel --real` (bench/channel_real.py, board_register.py, board_measure.py): registration of a real board photo onto its template, the
pooled slanted-edge MTF against a known Gaussian blur, and one-line errors for photos without a board."""
from __future__ import annotations

import subprocess
import sys

import cv2
import numpy as np
import pytest

from snapshot3d.bench import board_measure as bm
from snapshot3d.bench import board_register as br
from snapshot3d.builtin import shared_data_dir
from snapshot3d.errors import UserError
from snapshot3d.scanner.chart_measure import edge_mtf, mtf50


def _real(name: str):
    root = shared_data_dir()
    if root is None or not (root / "photos/aruco" / name).is_file():
        pytest.skip("../shared/data/photos/aruco is absent (real photos are not shipped with the package)")
    return cv2.imread(str(root / "photos/aruco" / name), cv2.IMREAD_COLOR)


def test_register_real_grid_board():
    """The opencv_contrib tutorial's photo of a printed 5 x 7 grid board: every marker matched to the
    template, the corners' RMS reprojection error under a pixel (a VGA webcam with some lens distortion)."""
    img = _real("gboriginal.png")
    quads, _ = br.find_quads(img)
    reg = br.register_board(quads, br.KNOWN_BOARDS["grid"])
    assert reg is not None
    assert reg["spec"].kind == "grid" and len(reg["matched"]) >= 33
    assert reg["rms_px"] < 0.8, reg["rms_px"]
    # the fitted homography puts the template's quads on the photo's: centre error well under a marker cell
    tq, _ = br.board_quads(reg["spec"])
    errs = [np.linalg.norm(cv2.perspectiveTransform(tq[t].reshape(-1, 1, 2), reg["H"]).reshape(4, 2)
                           - quads[p][order], axis=1).max() for p, t, order in reg["matched"]]
    assert max(errs) < 3.0


def _synthetic_photo(sigma: float, size=(700, 600), noise=0.0, seed=0) -> np.ndarray:
    """A grid board template seen in perspective, blurred by a Gaussian of `sigma` photo pixels in linear
    light (at 4x resolution, then point-sampled), sRGB-encoded, BGR uint8."""
    spec = br.KNOWN_BOARDS["grid"][3]
    tpl = br.board_template(spec, 240).astype(np.float32) / 255.0   # 1/4 photo px per template px
    refl = 0.03 + 0.8 * tpl
    th, tw = tpl.shape
    W, H = size
    src = np.float32([[0, 0], [tw, 0], [tw, th], [0, th]])
    dst = np.float32([[130, 40], [560, 75], [600, 560], [90, 530]]) * 4
    Hm = cv2.getPerspectiveTransform(src, dst)
    hr = cv2.warpPerspective(refl, Hm, (W * 4, H * 4), flags=cv2.INTER_LINEAR, borderValue=0.6)
    hr = cv2.GaussianBlur(hr, (0, 0), 4 * sigma)
    lin = hr[::4, ::4]
    if noise:
        lin = lin + np.random.default_rng(seed).normal(0, noise, lin.shape).astype(np.float32)
    lin = np.clip(lin, 0, 1)
    codes = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    g = np.round(codes * 255).astype(np.uint8)
    return np.repeat(g[..., None], 3, 2)


@pytest.mark.parametrize("sigma", [0.4, 0.9, 1.5])
def test_mtf_recovers_gaussian_blur(sigma):
    """MTF50 of a Gaussian of sigma px: sqrt(ln 2 / 2) / (pi sigma) cycles per pixel; the pooled ESF over the
    board's edges recovers it within 15 %, and the tone and noise read what was drawn."""
    img = _synthetic_photo(sigma)
    m = bm.measure_photo(img, br.KNOWN_BOARDS["grid"])
    want = np.sqrt(np.log(2) / 2) / (np.pi * sigma)
    assert m["mode"] == "board" and m["edges"] >= 20
    assert abs(m["mtf50_px"] / want - 1) < 0.15, (m["mtf50_px"], want)
    assert abs(m["contrast"] - 0.03 / 0.83) < 0.02
    assert m["noise_white"] < 1.0 and m["overshoot"] < 0.03


def test_esf_mtf_agrees_with_chart_measure():
    """On one slanted edge window, the (distance, value) variant gives the MTF50 that
    `scanner.chart_measure.edge_mtf` gives (the Tukey window in place of the Hamming one: within 8 %)."""
    n, sigma, ang = 64, 1.2, np.deg2rad(5.0)
    yy, xx = np.mgrid[0:n * 4, 0:n * 4] / 4.0
    step = ((xx - n / 2) * np.cos(ang) - (yy - n / 2) * np.sin(ang) > 0).astype(np.float64)
    roi = cv2.GaussianBlur(step, (0, 0), 4 * sigma)[::4, ::4]
    f, m = edge_mtf(roi, True)
    ref = mtf50(f, m)
    y, x = np.mgrid[0:n, 0:n].astype(np.float64)
    d = (x - n / 2) * np.cos(ang) - (y - n / 2) * np.sin(ang)
    f2, m2 = bm.esf_mtf(d.ravel(), roi.ravel(), 12.0)
    got = mtf50(f2, m2)
    want = np.sqrt(np.log(2) / 2) / (np.pi * sigma)
    assert abs(got / ref - 1) < 0.08, (got, ref)
    assert abs(got / want - 1) < 0.1, (got, want)


def test_photo_without_board_is_a_one_line_error(tmp_path):
    rng = np.random.default_rng(0)
    for img in (np.full((480, 640, 3), 128, np.uint8), rng.integers(0, 256, (480, 640, 3), dtype=np.uint8),
                cv2.GaussianBlur(rng.integers(0, 256, (480, 640, 3), dtype=np.uint8), (0, 0), 3)):
        with pytest.raises(UserError, match="no ArUco board") as e:
            bm.measure_photo(img)
        assert "\n" not in str(e.value)
    cv2.imwrite(str(tmp_path / "desk.png"), np.full((480, 640, 3), 128, np.uint8))
    proc = subprocess.run([sys.executable, "-m", "snapshot3d", "bench", "channel", "--real", "--photos",
                           str(tmp_path), "--out", str(tmp_path / "out")], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode != 0
    err = proc.stderr.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1 and "no board was measured" in err, err
    assert not (tmp_path / "out" / "channel_real.json").exists()
