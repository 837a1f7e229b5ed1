"""Metadata in the pixels (`scanner.pixelmeta`): the frame round-trips and its CRC refuses damage; the mark
reads back exactly from what sharing does to a snapshot (JPEG 60-95 with 4:2:0 chroma, twice; resizing to
256 and 1080 px; a few pixels cropped or padded) and reads nothing from an unmarked image; a snapshot file
(the file medium's) with its text stripped restores and decodes from the mark alone."""
import json
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli

from snapshot3d import formats
from snapshot3d.codecs.media import CODEC_MEDIUM
from snapshot3d.errors import UserError
from snapshot3d.scanner import pixelmeta as pm
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.qr import SheetMeta
from snapshot3d.scanner.snapfile import encode_snapshot, file_pixels, metas_agree, read_snapshot

ASSETS = Path(str(resources.files("snapshot3d") / "assets"))
META = SheetMeta(codec=formats.FILE_CODEC, box=(-0.55, -0.5, -0.45, 0.5, 0.6, 0.5), orbit=(2.7, 20.0, 40.0),
                 target=(0.0, 0.05, 0.0), planes=(64, 8), strength=1.0)


def _jpeg(rgb, q):
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [
        cv2.IMWRITE_JPEG_QUALITY, q, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420])
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]


def _resize(rgb, n):
    return cv2.resize(rgb, (n, n), interpolation=cv2.INTER_AREA if n < rgb.shape[0] else cv2.INTER_CUBIC)


def _host(name):
    return (load_host("builtin:" + name) * 255 + 0.5).astype(np.uint8)


@pytest.fixture(scope="module")
def marked():
    return {h: pm.mark(_host(h), META) for h in ("coffee", "camera", "astronaut")}


SHORT = pm.unpack(pm.pack(META))   # what the short frame carries: the numbers at float16


def test_frame_round_trip_and_crc():
    assert metas_agree(SHORT, META) and SHORT.box != META.box   # float16: the QR text's four digits, not more
    for frame in (pm.FRAME, pm.LEGACY_FRAMES[0]):
        data = pm.pack(META, frame)
        assert len(data) == frame.nbytes and pm.unpack(data) == (SHORT if frame.version == 2 else META)
        bare = SheetMeta(codec=formats.PRINT_CODEC)
        assert pm.unpack(pm.pack(bare, frame)) == bare
        for i in (0, 10, 30, frame.nbytes - 1):  # any single flipped bit is refused
            bad = bytearray(data)
            bad[i] ^= 0x10
            assert pm.unpack(bytes(bad)) is None
    with pytest.raises(ValueError, match="too long"):
        pm.pack(SheetMeta(codec="x" * 20), pm.LEGACY_FRAMES[0])
    with pytest.raises(ValueError, match="does not fit a version-2 mark"):
        pm.pack(SheetMeta(codec="other-1"))
    with pytest.raises(ValueError, match="does not fit a version-2 mark"):
        pm.pack(SheetMeta(codec=formats.FILE_CODEC, box=(0, 0, 0, 1e6, 1, 1)))


def test_every_codec_this_build_writes_has_a_mark_index():
    assert set(formats.FILE_CODECS) | {formats.PRINT_CODEC} <= set(formats.MARK_CODECS)


def test_unknown_codec_index_reads_as_an_unknown_codec():
    import struct
    import zlib

    body = bytearray(pm.pack(META)[:-4])
    body[2] = 200
    meta = pm.unpack(bytes(body) + struct.pack("<I", zlib.crc32(bytes(body))))
    assert meta is not None and meta.codec == "mark-codec-200" and meta.codec not in CODEC_MEDIUM


def test_a_meta_the_short_frame_cannot_hold_is_marked_in_the_long_one():
    meta = SheetMeta(codec="other-1", box=(-0.55, -0.5, -0.45, 0.5, 0.6, 0.5), planes=(32, 4))
    found = pm.find_meta(_jpeg(pm.mark(_host("coffee"), meta), 75))
    assert found is not None and found[0] == meta


def test_viterbi_corrects_scattered_errors(rng):
    bits = rng.integers(0, 2, pm.LEGACY_FRAMES[0].nbytes * 8)
    soft = 1.0 - 2.0 * pm.conv_encode(bits)
    flip = rng.choice(soft.size, 40, replace=False)   # 40 of 1164 coded bits wrong, scattered
    soft[flip] *= -0.8
    assert np.array_equal(pm.viterbi(soft + rng.normal(0, 0.3, soft.size)), bits)


def test_mark_is_faint(marked):
    for h, img in marked.items():
        mse = np.mean((img.astype(float) - _host(h)) ** 2)
        assert 10 * np.log10(255 ** 2 / mse) >= 42.0   # 42.4 dB measured (the version-1 frame: 40.7 at step 40)


@pytest.mark.parametrize("name,copy", [
    ("same", lambda x: x),
    ("jpeg95", lambda x: _jpeg(x, 95)),
    ("jpeg60", lambda x: _jpeg(x, 60)),
    ("jpeg60 then 75", lambda x: _jpeg(_jpeg(x, 60), 75)),
    ("256 px jpeg75", lambda x: _jpeg(_resize(x, 256), 75)),
    ("256 px and back", lambda x: _resize(_resize(x, 256), 380)),
    ("1080 px jpeg75", lambda x: _jpeg(_resize(x, 1080), 75)),
    ("crop 4 px", lambda x: _jpeg(np.ascontiguousarray(x[4:, :-3]), 90)),
    ("pad 4 px", lambda x: cv2.copyMakeBorder(x, 4, 0, 0, 4, cv2.BORDER_CONSTANT, value=(255, 255, 255))),
    # the file as `embed --medium file` writes it (4x), and copies of it
    ("4x file jpeg75", lambda x: _jpeg(file_pixels(x, 4), 75)),
    ("crop 4x file 3 and 6 px", lambda x: _jpeg(np.ascontiguousarray(file_pixels(x, 4)[3:, 1:-5]), 90)),
    ("pad 4x file 5 px", lambda x: cv2.copyMakeBorder(file_pixels(x, 4), 2, 3, 5, 0, cv2.BORDER_CONSTANT,
                                                      value=(255, 255, 255))),
    ("4x file resized to 1500 px", lambda x: _jpeg(_resize(file_pixels(x, 4), 1500), 90)),   # near 4x: not squares
])
def test_mark_survives_sharing(marked, name, copy):
    for img in marked.values():
        found = pm.find_meta(copy(img))
        assert found is not None, name
        meta, aligned = found
        assert meta == SHORT and aligned.shape == (380, 380, 3)
        if name.startswith(("crop", "pad")):  # realigned to the snapshot's grid, not just read
            err = np.abs(aligned[8:-8, 8:-8].astype(float) - img[8:-8, 8:-8]).mean()
            assert err < 3.0, (name, err)


@pytest.mark.parametrize("frame", pm.LEGACY_FRAMES, ids=lambda f: f"v{f.version} step {f.step:g}")
def test_marks_of_earlier_versions_still_read(frame):
    old = pm.mark(_host("chelsea"), META, frame)
    for copy in (lambda x: x, lambda x: _jpeg(x, 75), lambda x: _jpeg(np.ascontiguousarray(x[3:, 2:]), 90)):
        found = pm.find_meta(copy(old))
        assert found is not None and found[0] == META


def test_no_mark_reads_nothing(rng):
    for h in ("coffee", "chelsea", "astronaut", "camera"):
        host = _host(h)
        assert pm.find_meta(host) is None and pm.find_meta(_jpeg(host, 75)) is None
    assert pm.find_meta(rng.integers(0, 256, (380, 380, 3), dtype=np.uint8)) is None
    assert pm.find_meta(_host("coffee")[:300]) is None   # not square and not near the snapshot's size


def test_stripped_file_reads_from_pixels_and_text_must_agree(marked, tmp_path):
    img = marked["coffee"]
    plain = tmp_path / "copy.png"
    cv2.imwrite(str(plain), img[..., ::-1])                # no text chunk
    rgb, meta = read_snapshot(plain)
    assert meta == SHORT and np.array_equal(rgb, img)
    other = tmp_path / "other.png"
    other.write_bytes(encode_snapshot(img, SheetMeta(codec=formats.FILE_CODEC, box=(0, 0, 0, 1, 1, 1),
                                                     planes=(32, 4))))
    with pytest.raises(UserError, match="disagree"):
        read_snapshot(other)
    assert read_snapshot(other, meta_text="S3D2|hinet-1|b=0,0,0,1,1,1|p=32,4")[1].planes == (32, 4)  # --meta wins
    bare = tmp_path / "bare.png"
    cv2.imwrite(str(bare), _host("coffee")[..., ::-1])
    with pytest.raises(UserError, match="no mark readable"):
        read_snapshot(bare)


def test_shared_file_snapshot_restores_and_decodes_with_no_metadata(tmp_path):
    snap = tmp_path / "snap.png"
    proc = run_cli("embed", str(ASSETS / "spot-print.s3d"), "--medium", "file", "--refine", "0",
                   "--host", "builtin:chelsea", "-o", str(snap))
    assert proc.returncode == 0, proc.stderr
    shared = tmp_path / "shared.jpg"
    small = cv2.resize(cv2.imread(str(snap)), (300, 300), interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(shared), small, [cv2.IMWRITE_JPEG_QUALITY, 75])   # OpenCV writes no comment
    proc = run_cli("restore", str(shared), "-o", str(tmp_path / "back.s3d"))
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("decode", str(shared), "-o", str(tmp_path / "views"), "--views", "2", "--size", "64")
    assert proc.returncode == 0, proc.stderr
    assert "quality estimate: none (a snapshot file has no markers)" in proc.stdout
    report = json.loads((tmp_path / "views" / "report.json").read_text())
    assert report["source"] == "snapshot file (metadata from its pixels)" and report["medium"] == "file"
    cv2.imwrite(str(tmp_path / "plain.png"), np.full((300, 300, 3), 128, np.uint8))
    assert_one_line_error(run_cli("restore", str(tmp_path / "plain.png"), "-o", str(tmp_path / "x.s3d")),
                          "carries no snapshot3d metadata")
    assert not (tmp_path / "x.s3d").exists()


def test_a_file_written_at_4x_shrinks_back_exactly(marked):
    img = marked["coffee"]
    assert np.array_equal(pm.shrink_squares(file_pixels(img, 4), 4), img)
    cropped = file_pixels(img, 4)[3:, 2:]                     # squares cut at the top and left: found by their edges
    assert np.array_equal(pm.shrink_squares(cropped, 4), img[1:, 1:])
