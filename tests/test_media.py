"""The two media end to end: `embed --medium print|file` names its codec in the snapshot's metadata and
in the sheet's QR code; `restore` and `decode` pick the codec from there and refuse an unknown one in one
line; a print snapshot round-trips through its file, and a moderate photo of its print decodes."""
import json
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli

from snapshot3d import formats
from snapshot3d.codecs.media import CODEC_MEDIUM
from snapshot3d.scanner.snapfile import read_snapshot
from snapshot3d.scene import load_scene_file

ASSETS = Path(str(resources.files("snapshot3d") / "assets"))
SCENE = ASSETS / "spot-print.s3d"


def _plane_psnr(a, b) -> float:
    return float(10 * np.log10(4.0 / np.mean((a.planes() - b.planes()) ** 2)))


@pytest.fixture(scope="module")
def print_snapshot(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("print")
    snap = tmp / "snap.png"
    proc = run_cli("embed", str(SCENE), "--host", "builtin:chelsea", "-o", str(snap), "--report", str(tmp / "e.json"))
    assert proc.returncode == 0, proc.stderr
    return tmp, snap, json.loads((tmp / "e.json").read_text())


def test_print_embed_names_its_codec_and_keeps_the_host(print_snapshot):
    tmp, snap, rep = print_snapshot
    assert rep["medium"] == "print" and rep["codec"] == formats.PRINT_CODEC
    assert rep["host_psnr"] >= 31.9 and rep["embed_ms"] < 20_000   # designed encoder, numpy
    rgb, meta = read_snapshot(snap)
    assert meta.codec == formats.PRINT_CODEC and list(meta.planes) == [load_scene_file(SCENE).resolution,
                                                                       load_scene_file(SCENE).channels]


def test_print_snapshot_file_round_trip(print_snapshot):
    tmp, snap, _ = print_snapshot
    proc = run_cli("restore", str(snap), "-o", str(tmp / "back.s3d"), "--report", str(tmp / "r.json"))
    assert proc.returncode == 0, proc.stderr
    back, orig = load_scene_file(tmp / "back.s3d"), load_scene_file(SCENE)
    assert back.codes.shape == orig.codes.shape
    assert _plane_psnr(orig, back) >= 45.0   # 16x4 planes in chelsea: 53.0 dB measured
    rep = json.loads((tmp / "r.json").read_text())
    assert rep["codec"] == formats.PRINT_CODEC and rep["plane_rmse_expected"] > 0


def test_sheet_qr_names_the_codec_and_a_moderate_photo_decodes(print_snapshot):
    """sheet -> simulate moderate -> decode (torch blocked): the QR names print-1; views look like the scene."""
    from test_decode import run_blocked

    from snapshot3d.cameras import orbit_cameras
    from snapshot3d.metrics import psnr
    from snapshot3d.viewer.render import render_views
    from snapshot3d.viewer.runtime import field_models

    tmp, snap, _ = print_snapshot
    assert run_cli("sheet", str(snap), "-o", str(tmp / "sheet.pdf")).returncode == 0
    proc = run_cli("simulate", str(tmp / "sheet.pdf"), "-o", str(tmp / "photo.jpg"), "--severity", "moderate",
                   "--seed", "3")
    assert proc.returncode == 0, proc.stderr
    proc = run_blocked("decode", str(tmp / "photo.jpg"), "-o", str(tmp / "out"), "--views", "4", "--size", "96")
    assert proc.returncode == 0, proc.stderr
    assert "quality estimate" in proc.stdout
    rep = json.loads((tmp / "out" / "report.json").read_text())
    assert rep["codec"] == formats.PRINT_CODEC and rep["medium"] == "print"
    assert rep["scan"]["qr"]["codec"] == formats.PRINT_CODEC
    orig = load_scene_file(SCENE)
    c2w, intr = orbit_cameras(orig.orbit, 4, 96)
    ref = render_views(field_models(decoder=orig.decoder_version), orig.planes(), orig.box, c2w, intr, 96, 96)
    got = np.stack([cv2.cvtColor(cv2.imread(str(tmp / "out" / "views" / f"{i:03d}.png")), cv2.COLOR_BGR2RGB)
                    for i in range(4)]) / 255.0
    measured = psnr(got, ref)
    assert measured >= MODERATE_MIN_DB
    q = rep["quality_estimate"]
    assert abs(q["restore_psnr_expected_db"] - measured) < 6.0   # a calibrated estimate, not a constant


MODERATE_MIN_DB = 20.0


def test_file_medium_still_names_hinet(tmp_path):
    snap = tmp_path / "f.png"
    proc = run_cli("embed", str(ASSETS / "spot.s3d"), "--medium", "file", "--refine", "0", "-o", str(snap))
    assert proc.returncode == 0, proc.stderr
    assert read_snapshot(snap)[1].codec == formats.FILE_CODEC
    proc = run_cli("sheet", str(snap), "-o", str(tmp_path / "s.png"))
    assert proc.returncode == 0 and "made for the file medium" in proc.stderr


def test_snapshots_of_every_file_codec_still_restore():
    """A snapshot names the file codec that made it, and the build reads each codec it lists in FILE_CODECS with
    that codec's own ONNX graph (tests/data/spot-snapshot-hinet-1.png and -hinet-2.png were made by them): the
    restored planes match what the codec's torch network reads, and a snapshot read with another codec's graph
    is much worse (so the pick matters)."""
    from snapshot3d.codecs.file_layout import secret_to_planes
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.qr import SheetMeta
    from snapshot3d.train.codec.hinet import codec_path, embed_planes, load_codec, restore_secret
    from snapshot3d.viewer.media import restore_planes

    scene = load_scene_file(ASSETS / "spot.s3d")
    want = scene.planes()
    host = load_host("builtin:chelsea")
    got = {}
    for codec in formats.FILE_CODECS:
        net = load_codec(codec_path(codec))[0]
        snap = embed_planes(net, host, want)
        meta = SheetMeta(codec=codec, box=scene.box, orbit=scene.orbit, planes=(scene.resolution, scene.channels))
        planes, info = restore_planes(snap, meta)
        ref = secret_to_planes(restore_secret(net, snap), scene.resolution, scene.channels)
        assert info == {} and np.abs(planes - np.clip(ref, -1, 1)).max() < 0.02, codec
        got[codec] = float(10 * np.log10(4.0 / np.mean((planes - want) ** 2)))
        assert got[codec] > 22.0, got   # unrefined snapshots: hinet-1 23.5, hinet-2 26.0, hinet-3 26.4 dB in plane space
        for other in set(formats.FILE_CODECS) - {codec}:
            wrong = restore_planes(snap, SheetMeta(codec=other, box=meta.box, orbit=meta.orbit, planes=meta.planes))[0]
            assert float(10 * np.log10(4.0 / np.mean((wrong - want) ** 2))) < got[codec] - 3, (codec, other)
    for name, codec in (("spot-snapshot.png", formats.FILE_CODEC), ("spot-snapshot-hinet-2.png", "hinet-2"),
                        ("spot-snapshot-hinet-1.png", "hinet-1")):
        rgb, meta = read_snapshot(Path(__file__).parent / "data" / name)   # files made by embed, refined 20 steps
        assert meta.codec == codec and CODEC_MEDIUM[codec] == "file"
        planes = restore_planes(rgb, meta)[0]
        assert float(10 * np.log10(4.0 / np.mean((planes - want) ** 2))) > 27.5, name  # 29.3 and 30.7 when made


def test_unknown_codec_is_refused_in_one_line(print_snapshot, tmp_path):
    from snapshot3d.scanner.qr import SheetMeta
    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.scanner.snapfile import write_snapshot

    _, snap, _ = print_snapshot
    rgb, meta = read_snapshot(snap)
    odd = SheetMeta(codec="print-9", box=meta.box, orbit=meta.orbit, planes=meta.planes)
    write_snapshot(tmp_path / "odd.png", rgb, odd)
    assert_one_line_error(run_cli("restore", str(tmp_path / "odd.png"), "-o", str(tmp_path / "x.s3d")),
                          "unknown codec id 'print-9'")
    sheet = render_sheet(rgb, odd, 2)
    cv2.imwrite(str(tmp_path / "odd-photo.png"), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    proc = run_cli("decode", str(tmp_path / "odd-photo.png"), "-o", str(tmp_path / "out"))
    assert_one_line_error(proc, "unknown codec id 'print-9'")
    assert not (tmp_path / "x.s3d").exists() and not (tmp_path / "out").exists()


def test_embed_refuses_planes_a_medium_cannot_carry(tmp_path):
    from snapshot3d.scene import Orbit, Scene, save_scene
    big = Scene(codes=np.zeros((3, 4, 80, 80), np.uint8), box=np.array([[-1] * 3, [1] * 3]), orbit=Orbit(3.0))
    save_scene(big, tmp_path / "big.s3d")
    assert_one_line_error(run_cli("embed", str(tmp_path / "big.s3d"), "-o", str(tmp_path / "s.png")),
                          "print codec carries planes")
    assert not (tmp_path / "s.png").exists()


def test_page_decodes_the_current_file_codec_itself():
    """The page restores in the browser only snapshots of the codec it names (others go to the server), so its
    constant must be the file codec `embed` writes now."""
    import re
    js = (Path(__file__).resolve().parents[1] / "viewer" / "static" / "local.js").read_text()
    assert re.findall(r'FILE_CODEC = "([^"]+)"', js) == [formats.FILE_CODEC]


def test_every_codec_embed_writes_ships_its_quality_calibration():
    """A sheet made with any codec `embed` writes decodes with an expected restore_psnr (bench decode
    writes the lines; a new codec without one would decode with the estimate null)."""
    from snapshot3d.viewer.quality import quality_estimate
    for codec in (formats.PRINT_CODEC, formats.FILE_CODEC):   # the print codec reads its views term
        q = quality_estimate(codec, pilot_psnr=30.0, plane_rmse=0.1, views_psnr=27.0)
        assert q["restore_psnr_expected_db"] is not None and 10 < q["restore_psnr_expected_db"] < 60, codec
        assert q["calibration"]["held_out_rmse_db"] < 3.0, codec


def test_a_print_of_a_scene_with_its_own_head_decodes_with_it_and_warns_without_it(tmp_path):
    """A scene with its own head: sheet -> moderate photo -> decode (torch blocked) renders with the head read from
    the two codes beside the QR code; with one of them inked over, decode still renders, with the shared head, and
    says so in one warning line."""
    from dataclasses import replace

    from test_decode import run_blocked

    from snapshot3d.cameras import orbit_cameras
    from snapshot3d.head import encode_head
    from snapshot3d.metrics import psnr
    from snapshot3d.scene import save_scene
    from snapshot3d.viewer.render import render_views
    from snapshot3d.viewer.runtime import scene_models

    scene = replace(load_scene_file(SCENE), head=encode_head(np.random.default_rng(0).normal(0, 0.05, (4, 33))))
    save_scene(scene, tmp_path / "h.s3d")
    assert run_cli("embed", str(tmp_path / "h.s3d"), "--host", "builtin:chelsea", "-o",
                   str(tmp_path / "snap.png")).returncode == 0
    assert run_cli("sheet", str(tmp_path / "snap.png"), "-o", str(tmp_path / "sheet.pdf")).returncode == 0
    sheet = cv2.imread(str(tmp_path / "sheet.png"))
    k = sheet.shape[1] // (formats.SHEET_BOX[2] - formats.SHEET_BOX[0])
    x0, y0, x1, y1 = formats.HEAD_CODE_BOXES[0]
    sx0, sy0 = formats.SHEET_BOX[:2]
    inked = sheet.copy()
    inked[(y0 + 20 - sy0) * k:(y1 - 20 - sy0) * k, (x0 + 10 - sx0) * k:(x1 - 10 - sx0) * k] = 0
    cv2.imwrite(str(tmp_path / "inked.png"), inked)
    c2w, intr = orbit_cameras(scene.orbit, 4, 96)
    ref = render_views(scene_models(scene), scene.planes(), scene.box, c2w, intr, 96, 96)
    got = {}
    for name in ("sheet", "inked"):
        assert run_cli("simulate", str(tmp_path / f"{name}.png"), "-o", str(tmp_path / f"{name}.jpg"), "--severity",
                       "moderate", "--seed", "3").returncode == 0
        proc = run_blocked("decode", str(tmp_path / f"{name}.jpg"), "-o", str(tmp_path / name), "--views", "4",
                           "--size", "96")
        assert proc.returncode == 0, proc.stderr
        rep = json.loads((tmp_path / name / "report.json").read_text())
        views = np.stack([cv2.cvtColor(cv2.imread(str(tmp_path / name / "views" / f"{i:03d}.png")), cv2.COLOR_BGR2RGB)
                          for i in range(4)]) / 255.0
        got[name] = (rep, proc.stdout, psnr(views, ref))
    rep, out, measured = got["sheet"]
    assert rep["own_head"] and not rep["head_codes_unread"] and "off-colour" not in out
    assert measured >= MODERATE_MIN_DB
    rep, out, measured_inked = got["inked"]
    assert not rep["own_head"] and rep["head_codes_unread"]
    assert sum("the scene's own decoder head) could not be read" in line for line in out.splitlines()) == 1
    assert measured_inked < measured - 1.0   # the shared head is not the scene's
