"""`snapshot3d embed` and `restore` with the shipped codec: round trips through a PNG and a JPEG-75
file, and one-line errors for bad inputs."""
import json
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli

from snapshot3d import formats
from snapshot3d.scene import Orbit, Scene, load_scene_file, save_scene

SPOT = Path(str(resources.files("snapshot3d") / "assets" / "spot.s3d"))


run = run_cli



def _plane_psnr(a: Scene, b: Scene) -> float:
    mse = np.mean((a.planes() - b.planes()) ** 2)
    return 10 * np.log10(4.0 / mse)  # planes span [-1, 1]


JPEG75_SHORTFALL = pytest.mark.xfail(strict=True, reason="issue 4 shortfall: the shipped codec does not survive a "
                                     "JPEG-75 snapshot file well, even refined at embed time and written at 4x (plane "
                                     "PSNR 20.2 dB after 20 steps; 16.6 for a 380-px file)")


@pytest.mark.parametrize("ext,quality,min_host,min_planes", [
    # --refine 20: planes measured 28.4 dB at host 32.2 dB (22.8 unrefined; the former schedule, whose host weight let
    # the host fall, gave 29.9 at 31.8); the pixel mark's step of 40 (issue 15) costs file snapshots about 0.4 dB of host
    (".png", 95, 32.0, 28.0),
    pytest.param(".jpg", 75, 32.0, 24.0, marks=[JPEG75_SHORTFALL, pytest.mark.slow]),  # 90 s to show a known gap
])
def test_embed_restore_round_trip(tmp_path, ext, quality, min_host, min_planes):
    """The file medium (20 refinement steps keep the test short; the default is formats.FILE_REFINE_STEPS)."""
    snap, out = tmp_path / f"snap{ext}", tmp_path / "back.s3d"
    proc = run("embed", str(SPOT), "--medium", "file", "--refine", "20", "--host", "builtin:coffee", "-o", str(snap),
               "--jpeg-quality", str(quality), "--report", str(tmp_path / "e.json"))
    assert proc.returncode == 0, proc.stderr
    rep = json.loads((tmp_path / "e.json").read_text())
    assert rep["host_psnr"] >= min_host and rep["host_ssim"] > 0.75, rep  # measured 32.2 dB, 0.77 (coffee)
    assert cv2.imread(str(snap)).shape == (formats.FILE_SCALE * formats.SNAPSHOT_SIZE,) * 2 + (3,)   # written at 4x
    proc = run("restore", str(snap), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    orig, back = load_scene_file(SPOT), load_scene_file(out)
    assert back.codes.shape == orig.codes.shape
    np.testing.assert_allclose(back.box, orig.box, rtol=1e-3)
    assert abs(back.orbit.radius - orig.orbit.radius) < 1e-3 * orig.orbit.radius
    assert _plane_psnr(orig, back) >= min_planes


@pytest.mark.parametrize("medium,target", [("file", 38.0), ("print", 36.0)])
def test_embed_keeps_the_host_fidelity_asked_for(tmp_path, medium, target):
    """--host-psnr picks the strength for this host and scene (file: the paper's 38 dB, within 0.3 dB over);
    the snapshot's metadata carries it, so the restore divides by the same strength."""
    snap, out = tmp_path / "snap.png", tmp_path / "back.s3d"
    proc = run("embed", str(SPOT), "--medium", medium, "--refine", "0", "--host-psnr", str(target),
               "--host", "builtin:chelsea", "-o", str(snap), "--report", str(tmp_path / "e.json"))
    assert proc.returncode == 0, proc.stderr
    rep = json.loads((tmp_path / "e.json").read_text())
    assert target <= rep["host_psnr"] <= target + 0.3, rep
    assert rep["strength"] < 1.0 and f"strength {rep['strength']:g}" in proc.stdout
    if medium == "file":
        assert run("restore", str(snap), "-o", str(out)).returncode == 0
        assert _plane_psnr(load_scene_file(SPOT), load_scene_file(out)) >= 23.0  # measured 25.2 (unrefined, 38.01 dB)


def test_embed_refuses_planes_the_codec_cannot_carry(tmp_path):
    scene = Scene(codes=np.zeros((3, 12, 64, 64), np.uint8), box=np.array([[-1] * 3, [1] * 3]), orbit=Orbit(3.0))
    save_scene(scene, tmp_path / "c12.s3d")
    assert_one_line_error(run("embed", str(tmp_path / "c12.s3d"), "--medium", "file", "-o", str(tmp_path / "s.png")),
                          "at most 8 channels")
    assert not (tmp_path / "s.png").exists()


def test_restore_bad_inputs(tmp_path):
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((100, 120, 3), np.uint8))
    assert_one_line_error(run("restore", str(small), "-o", str(tmp_path / "x.s3d")),
                          "small.png (120x100) carries no snapshot3d metadata")
    bare = tmp_path / "bare.png"
    cv2.imwrite(str(bare), np.zeros((380, 380, 3), np.uint8))
    assert_one_line_error(run("restore", str(bare), "-o", str(tmp_path / "x.s3d")), "no snapshot3d metadata")
    assert_one_line_error(run("restore", str(bare), "-o", str(tmp_path / "x.s3d"), "--meta",
                        "S3D1|other-codec|b=-1,-1,-1,1,1,1|p=64,8"), "unknown codec id")
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(bare.read_bytes()[:500])
    assert_one_line_error(run("restore", str(corrupt), "-o", str(tmp_path / "x.s3d")), "corrupt")
    assert_one_line_error(run("restore", str(tmp_path / "gone.png"), "-o", str(tmp_path / "x.s3d")),
                          "snapshot not found")
    assert_one_line_error(run("restore", str(tmp_path), "-o", str(tmp_path / "x.s3d")),
                          "is a folder; give the snapshot file itself")
    text = tmp_path / "notes.png"
    text.write_text("not an image at all")
    proc = run("restore", str(text), "-o", str(tmp_path / "x.s3d"))
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert not (tmp_path / "x.s3d").exists()


def test_embed_bad_host_and_output(tmp_path):
    assert_one_line_error(run("embed", str(SPOT), "--host", "builtin:nothing", "-o", str(tmp_path / "s.png")),
                    "unknown bundled host")
    assert_one_line_error(run("embed", str(SPOT), "-o", str(tmp_path / "s.bmp")), "cannot write")
    assert_one_line_error(run("embed", str(SPOT), "-o", str(tmp_path / "s.png"), "--strength", "0"), "--strength")
    assert_one_line_error(run("embed", str(SPOT), "-o", str(tmp_path / "s.png"), "--refine", "-1"), "--refine")
    assert_one_line_error(run("embed", str(SPOT), "-o", str(tmp_path / "s.png"), "--strength", "0.5", "--host-psnr",
                              "38"), "give --strength or --host-psnr, not both")
    assert_one_line_error(run("embed", str(SPOT), "-o", str(tmp_path / "s.png"), "--host-psnr", "90"),
                          "--host-psnr must be in [20, 60] dB")
    assert_one_line_error(run("embed", str(SPOT), "--medium", "file", "-o", str(tmp_path / "s.png"), "--host-psnr",
                              "55"), "the file codec keeps at most")
    small = tmp_path / "small.png"   # a thumbnail would be enlarged past twice: refused, naming its size
    cv2.imwrite(str(small), np.full((120, 160, 3), 128, np.uint8))
    assert_one_line_error(run("embed", str(SPOT), "--host", str(small), "-o", str(tmp_path / "s.png")),
                          "host photo small.png is 160x120: too small")
    assert not (tmp_path / "s.png").exists()


def test_embed_hints_at_the_budget_for_planes_a_print_cannot_carry():
    """Plain `fit` writes 64x8 planes; a print of them restores ~6 dB worse than the budget's 16x4 (the codec
    curve), so `embed` says in one line what to run instead; a budgeted scene and the file medium get no hint."""
    from snapshot3d.paths import asset
    from snapshot3d.scene import load_scene_file
    from snapshot3d.train.codec.commands import payload_hint

    big, small = load_scene_file(asset("spot.s3d")), load_scene_file(asset("spot-print.s3d"))
    hint = payload_hint("print", big)
    assert (big.resolution, big.channels) == (64, 8) and hint.startswith("hint: 64x8 planes") and "\n" not in hint
    assert "--budget auto --medium print" in hint
    assert payload_hint("print", small) is None and payload_hint("file", big) is None
