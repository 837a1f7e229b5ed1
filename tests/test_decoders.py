"""Shared decoder versions: a scene names the decoder it was fitted for, every snapshot carries it (the
metadata line's d=, the pixel mark's presence byte), and decode renders with that version's graphs, so
scenes and snapshots of `tri-dec-1` still decode after `tri-dec-2` became the default."""
import json
from dataclasses import replace
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import assert_one_line_error
from test_decode import run_blocked

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.scanner import pixelmeta as pm
from snapshot3d.scanner.qr import SheetMeta, check_meta, decode_payload, encode_payload, scene_meta
from snapshot3d.scene import load_scene_file

ASSETS = Path(str(resources.files("snapshot3d") / "assets"))
DATA = Path(__file__).resolve().parent / "data"
BOX = (-1.0, -1.0, -1.0, 1.0, 1.0, 1.0)


def test_every_decoder_ships_its_weights_and_graphs():
    assert formats.DECODER_VERSION in formats.DECODERS and len(set(formats.DECODERS)) == len(formats.DECODERS)
    for v in formats.DECODERS:
        assert formats.decoder_number(v) is not None
        for name in (f"decoder-{v}.npz", f"decoder-{v}.json", f"project-{v}.onnx", f"field-{v}.onnx"):
            assert (ASSETS / name).is_file(), name
    assert formats.decoder_number("tri-dec-12") == 12 and formats.decoder_number("other-2") is None


def test_metadata_line_carries_the_decoder():
    old = SheetMeta(codec=formats.PRINT_CODEC, box=BOX, planes=(16, 4))
    assert "d=" not in encode_payload(old)                      # tri-dec-1 sheets read as before
    assert decode_payload(encode_payload(old)).decoder_version == "tri-dec-1"
    new = SheetMeta(codec=formats.PRINT_CODEC, box=BOX, planes=(16, 4), decoder=2)
    back = decode_payload(encode_payload(new))
    assert encode_payload(new).endswith("|d=2") and back == new and back.decoder_version == "tri-dec-2"
    with pytest.raises(ValueError, match="field d="):
        decode_payload(encode_payload(old) + "|d=1.5")
    with pytest.raises(UserError, match="fitted for decoder tri-dec-9 .*this build has decoder tri-dec-1, tri-dec-2"):
        check_meta(SheetMeta(codec=formats.PRINT_CODEC, box=BOX, planes=(16, 4), decoder=9))
    with pytest.raises(UserError, match="fitted for decoder tri-dec-0"):   # d=0 is no decoder, not tri-dec-1
        check_meta(decode_payload(encode_payload(old) + "|d=0"))


def test_pixel_mark_carries_the_decoder():
    for frame in (pm.FRAME, pm.LEGACY_FRAMES[0]):
        for d in (None, 2, 8):
            meta = SheetMeta(codec=formats.FILE_CODEC, box=BOX, planes=(64, 8), decoder=d)
            assert pm.unpack(pm.pack(meta, frame)).decoder == d
    for bad in (0, 9):
        with pytest.raises(ValueError, match="does not fit the pixel mark"):
            pm.pack(SheetMeta(codec=formats.FILE_CODEC, decoder=bad))


def test_scene_of_each_decoder_writes_its_version():
    for name in ("spot.s3d", "spot-print.s3d"):
        scene = load_scene_file(ASSETS / name)
        assert scene.decoder_version in formats.DECODERS
        assert scene_meta(scene).decoder_version == scene.decoder_version


def _views_psnr(out: Path, scene, n: int, size: int, decoder: str) -> float:
    from snapshot3d.cameras import orbit_cameras
    from snapshot3d.metrics import psnr
    from snapshot3d.viewer.render import render_views
    from snapshot3d.viewer.runtime import field_models
    c2w, intr = orbit_cameras(scene.orbit, n, size)
    ref = render_views(field_models(decoder=decoder), scene.planes(), scene.box, c2w, intr, size, size)
    got = np.stack([cv2.cvtColor(cv2.imread(str(out / "views" / f"{i:03d}.png")), cv2.COLOR_BGR2RGB)
                    for i in range(n)]) / 255.0
    return psnr(got, ref)


@pytest.mark.parametrize("decoder", formats.DECODERS)
def test_snapshots_of_every_decoder_decode_with_their_own(tmp_path, decoder):
    """A print snapshot file of a scene of each decoder version (the shipped print scene, labelled as fitted for
    that version) decodes with that version's graphs: its views match the original rendered by that decoder, and
    not the other's."""
    from snapshot3d.codecs import print_embed
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.snapfile import write_snapshot
    scene = replace(load_scene_file(ASSETS / "spot-print.s3d"), decoder_version=decoder)
    snap = print_embed.embed(load_host("builtin:chelsea"), scene.planes())
    write_snapshot(tmp_path / "snap.png", snap, scene_meta(scene, formats.PRINT_CODEC))
    proc = run_blocked("decode", str(tmp_path / "snap.png"), "-o", str(tmp_path / "out"), "--views", "2", "--size", "96")
    assert proc.returncode == 0, proc.stderr
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["decoder"] == decoder and load_scene_file(tmp_path / "out" / "scene.s3d").decoder_version == decoder
    other = next(v for v in formats.DECODERS if v != decoder)
    own, wrong = (_views_psnr(tmp_path / "out", scene, 2, 96, v) for v in (decoder, other))
    assert own > 30 and own > wrong + 5, (own, wrong)


def test_old_file_snapshot_still_decodes(tmp_path):
    """tests/data/spot-snapshot.png was written before tri-dec-2 (no d= field, a mark of zero decoder bits): it
    decodes with tri-dec-1 and gives spot's views."""
    proc = run_blocked("decode", str(DATA / "spot-snapshot.png"), "-o", str(tmp_path / "out"), "--views", "2",
                       "--size", "96")
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "out" / "report.json").read_text())["decoder"] == "tri-dec-1"
    assert _views_psnr(tmp_path / "out", load_scene_file(ASSETS / "spot.s3d"), 2, 96, "tri-dec-1") > 28


def test_scene_file_of_an_unknown_decoder_is_refused(tmp_path):
    from snapshot3d.scene import save_scene
    save_scene(replace(load_scene_file(ASSETS / "spot-print.s3d"), decoder_version="tri-dec-7"), tmp_path / "x.s3d")
    with pytest.raises(UserError, match="fitted for decoder 'tri-dec-7'"):
        load_scene_file(tmp_path / "x.s3d")
    proc = run_blocked("embed", str(tmp_path / "x.s3d"), "-o", str(tmp_path / "s.png"))
    assert_one_line_error(proc, "fitted for decoder 'tri-dec-7'")
