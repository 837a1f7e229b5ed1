"""Hostile inputs (issue 36): one regression test per class of input that once ended in a traceback, a
non-finite success or unbounded memory. Each builds the exact input the fuzz campaign found. Scene files
(classes 5 to 8) are in test_hostile_scenes.py."""
import io
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli
from PIL import Image, PngImagePlugin

from snapshot3d import formats, validate
from snapshot3d.cameras import view_camera
from snapshot3d.errors import UserError
from snapshot3d.paths import asset
from snapshot3d.scanner.imageio_safe import read_image_bgr
from snapshot3d.scanner.qr import check_meta, decode_payload
from snapshot3d.scanner.scan import scan_image
from snapshot3d.scanner.snapfile import metadata_text, read_snapshot
from snapshot3d.scene import Orbit

DATA = Path(__file__).parent / "data"
SNAPSHOT = DATA / "spot-snapshot.png"
BOX = "b=-0.5819,-1.06,-1.043,0.5819,1.06,1.043"


def _meta_text(codec="hinet-3", **fields):
    """A metadata text like the shipped snapshot's, `fields` (key -> value text) replacing its fields."""
    parts = {"b": BOX[2:], "o": "4.202,20,40", "t": "0,0,0", "p": "64,8", "s": "1", **fields}
    return "|".join([f"{formats.QR_MAGIC}1", codec] + [f"{k}={v}" for k, v in parts.items()])


def _flat_png(path, text, ext=".png"):
    """A 380x380 grey image with no mark in its pixels, carrying `text` as its PNG text chunk or JPEG comment."""
    img = Image.fromarray(np.full((380, 380, 3), 128, np.uint8))
    if ext == ".png":
        info = PngImagePlugin.PngInfo()
        info.add_text("snapshot3d", text)
        img.save(path, pnginfo=info)
    else:
        img.save(path, quality=90, comment=text.encode())
    return path


# --- class 1: very thin images ---

@pytest.mark.parametrize("h,w", [(3, 40000), (1, 65000), (40000, 3)])
def test_thin_images_are_refused_in_one_line(tmp_path, h, w):
    from snapshot3d.viewer.decode import read_input

    path = tmp_path / "thin.png"
    cv2.imwrite(str(path), np.full((h, w, 3), 200, np.uint8))
    with pytest.raises(UserError, match="too small to hold a sheet"):
        read_input(path)
    with pytest.raises(UserError, match="too small to hold a sheet"):
        scan_image(np.full((h, w, 3), 200, np.uint8))


def test_thin_photo_but_large_enough_scans_without_a_resize_assert():
    img = np.full((400, 60000, 3), 255, np.uint8)      # factor by the long side would shrink the short to 0-ish
    with pytest.raises(UserError, match="no sheet|no snapshot3d sheet|flat|washed"):
        scan_image(img)


# --- classes 2 and 3: metadata out of range, or not finite, in each carrier ---

@pytest.mark.parametrize("codec,planes", [("print-2", "100,8"), ("print-2", "0,8"), ("print-2", "64,13"),
                                          ("print-2", "3,4"), ("hinet-3", "64,9"), ("hinet-3", "100,8")])
def test_plane_size_out_of_the_codecs_range_is_refused(tmp_path, codec, planes):
    text = _meta_text(codec, p=planes)
    for ext in (".png", ".jpg"):    # the text chunk and the JPEG comment
        path = _flat_png(tmp_path / f"snap{ext}", text, ext)
        with pytest.raises(UserError, match=rf"p={planes} is out of range for codec {codec}"):
            read_snapshot(path)
    with pytest.raises(UserError, match=rf"p={planes} is out of range"):   # the QR text, as --meta passes it
        read_snapshot(SNAPSHOT, text)


@pytest.mark.parametrize("field", ["p=64,-1", "p=inf,8", "p=1e309,8", "p=nan,8", "p=64.5,8", "b=inf,0,0,1,1,1",
                                   "o=1e309,20,40", "t=nan,0,0", "s=-inf", "s=1e309"])
def test_non_finite_or_malformed_numbers_are_one_line_errors(tmp_path, field):
    key, value = field.split("=")
    text = _meta_text(**{key: value})
    with pytest.raises(ValueError, match="malformed"):
        decode_payload(text)
    with pytest.raises(UserError, match="malformed field"):
        read_snapshot(_flat_png(tmp_path / "s.png", text))
    with pytest.raises(UserError, match="malformed field"):
        read_snapshot(SNAPSHOT, text)


def test_edited_text_of_a_real_snapshot_is_a_one_line_error(tmp_path):
    """The text is parsed before it is compared with the mark: p=1e309 once raised OverflowError there."""
    rgb = np.asarray(Image.open(SNAPSHOT).convert("RGB"))
    assert metadata_text(SNAPSHOT) == _meta_text()
    for field in ("p=1e309,8", "p=inf,8", "s=nan"):
        info = PngImagePlugin.PngInfo()
        info.add_text("snapshot3d", _meta_text(**dict([field.split("=")])))
        path = tmp_path / "edited.png"
        Image.fromarray(rgb).save(path, pnginfo=info)
        with pytest.raises(UserError, match="edited.png: malformed field"):
            read_snapshot(path)


@pytest.mark.parametrize("field,match", [
    ("b=0,0,0,0,1,1", "box b= must have x1 > x0"), ("b=1,1,1,-1,-1,-1", "box b= must have x1 > x0"),
    ("b=-1e9,0,0,1,1,1", r"box b=\[0\] must be a finite number in \[-100000, 100000\]"),
    ("o=0,20,40", "orbit o= radius"), ("o=-1,20,40", "orbit o= radius"),
    ("o=4,20,0", r"fov_deg must be a finite number in \[1, 170\]"), ("o=4,20,180", "fov_deg"),
    ("o=4,20,1e9", "fov_deg"), ("o=4,95,40", "elevation_deg"), ("t=1e9,0,0", "target t="),
    ("s=0", r"strength s= must be a finite number in \[0.01, 100\]"), ("s=-1", "strength s=")])
def test_degenerate_numbers_in_metadata_are_refused(tmp_path, field, match):
    text = _meta_text(**dict([field.split("=")]))
    with pytest.raises(UserError, match=match):
        read_snapshot(_flat_png(tmp_path / "s.png", text))
    with pytest.raises(UserError, match=match):
        check_meta(decode_payload(text))


def test_metadata_text_has_a_length_limit():
    with pytest.raises(ValueError, match="over 512 characters"):
        decode_payload(_meta_text() + "|x=" + "1" * 600)
    with pytest.raises(UserError, match="unknown codec id 'xxxxxxxx"):
        check_meta(decode_payload("S3D1|" + "x" * 300))


def test_a_mark_in_the_pixels_with_a_nan_is_refused():
    from snapshot3d.scanner.pixelmeta import pack, unpack
    from snapshot3d.scanner.qr import SheetMeta

    meta = SheetMeta(codec="hinet-3", box=(0, 0, 0, 1, 1, 1), orbit=(3.0, 20.0, 40.0), planes=(64, 8), strength=1.0)
    read = unpack(pack(meta))
    assert check_meta(read) is read
    bad = SheetMeta(codec="hinet-3", box=(0, 0, 0, 1, 1, 1), orbit=(float("nan"), 20.0, 40.0), planes=(64, 8))
    with pytest.raises(UserError, match="orbit o= radius"):
        check_meta(unpack(pack(bad, _legacy_frame())))


def _legacy_frame():
    from snapshot3d.scanner.pixelmeta import LEGACY_FRAMES
    return LEGACY_FRAMES[0]


# --- class 4: the print reader never returns a non-finite number as a success ---

def test_print_reading_that_measures_nothing_is_finite_or_an_error(monkeypatch):
    """Metadata naming planes the snapshot does not carry: the reading is finite (the band combination keeps the
    designed filter of a carrier it would read with the wrong sign; 31x1 once overflowed to an infinite noise and
    a NaN rmse), and a reading that is not finite is still refused in one line."""
    from snapshot3d.viewer import decode
    from snapshot3d.viewer.decode import restore_checked

    rgb, _ = read_snapshot(SNAPSHOT)
    for p in ("31,1", "16,4"):
        planes, info = restore_checked(rgb, decode_payload(_meta_text("print-2", p=p)))
        assert np.all(np.isfinite(planes)) and all(np.isfinite(v) for v in info.values()), (p, info)
    monkeypatch.setattr(decode, "restore_planes", lambda s, m: (np.zeros((3, 4, 16, 16), np.float32),
                                                                 {"plane_rmse_expected": float("nan")}))
    with pytest.raises(UserError, match="read no usable signal") as e:
        restore_checked(rgb, decode_payload(_meta_text("print-2", p="16,4")))
    assert "\n" not in str(e.value) and "plane_rmse_expected nan" in str(e.value)


# --- class 8 (the camera): a view from a distance of 1e-300 ---

@pytest.mark.parametrize("distance", [1e-300, 0.0, -1.0, float("nan"), float("inf")])
def test_view_camera_refuses_a_degenerate_distance(distance):
    with pytest.raises(UserError, match="distance"):
        view_camera(Orbit(3.0), 0.0, 20.0, distance, 64)
    c2w, intr = view_camera(Orbit(3.0), 0.0, 20.0, 1e-3, 64)
    assert np.isfinite(c2w).all() and np.isfinite(intr).all()


# --- class 9: quiet libraries ---

def _noisy_jpeg(path, h=480, w=640, truncate=False):
    """A JPEG with bytes between its scan and its end marker (libjpeg warns "Corrupt JPEG data") or cut short."""
    img = np.random.default_rng(0).integers(0, 256, (h, w, 3), dtype=np.uint8)
    data = cv2.imencode(".jpg", img)[1].tobytes()
    path.write_bytes(data[:len(data) // 2] if truncate else data[:-2] + b"\x00\x11\x22\x33" + data[-2:])
    return path


def test_cli_stderr_is_exactly_one_line_for_a_corrupt_or_truncated_jpeg(tmp_path):
    raw = subprocess.run([sys.executable, "-c", "import cv2, numpy as np, sys; d = open(sys.argv[1], 'rb').read(); "
                          "cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_COLOR)", str(_noisy_jpeg(tmp_path / "n.jpg"))],
                         capture_output=True, text=True)
    assert "Corrupt JPEG data" in raw.stderr   # the library does warn on this input
    for name, truncate in (("noisy.jpg", False), ("cut.jpg", True)):
        proc = run_cli("decode", str(_noisy_jpeg(tmp_path / name, truncate=truncate)), "-o", str(tmp_path / "out"))
        assert_one_line_error(proc, "snapshot3d decode: error:")
        assert "Corrupt JPEG" not in proc.stderr
    ok = subprocess.run([sys.executable, "-c", "import sys; from snapshot3d.scanner.imageio_safe import read_image_bgr; "
                         "print(read_image_bgr(sys.argv[1]).shape)", str(tmp_path / "noisy.jpg")],
                        capture_output=True, text=True)
    assert ok.returncode == 0 and ok.stdout.strip() == "(480, 640, 3)" and ok.stderr == ""


def test_damaged_tiff_headers_print_nothing(tmp_path, capfd):
    """Pillow logs a TIFF's absurd samples per pixel at ERROR before it raises: not on our stderr."""
    buf = io.BytesIO()
    Image.fromarray(np.zeros((40, 50, 3), np.uint8)).save(buf, format="TIFF")
    rng = np.random.default_rng(0)
    errors = 0
    for _ in range(150):
        data = bytearray(buf.getvalue())
        for i in rng.integers(0, 200, 4):
            data[i] = rng.integers(0, 256)
        (tmp_path / "t.tif").write_bytes(bytes(data))
        try:
            read_image_bgr(tmp_path / "t.tif")
        except UserError:
            errors += 1
    assert errors > 50 and capfd.readouterr().err == ""


# --- capture files (transforms.json) ---

def _capture(tmp_path, transforms: dict, n=3):
    for i in range(n):
        cv2.imwrite(str(tmp_path / f"{i}.png"), np.full((16, 16, 3), 100 + i, np.uint8))
    (tmp_path / "transforms.json").write_text(json.dumps(transforms))
    return str(tmp_path / "transforms.json")


def _frame(i, **kw):
    m = np.eye(4)
    m[:3, 3] = (0, -3 + i * 0.1, 0.5)
    return {"file_path": f"{i}.png", "transform_matrix": m.tolist(), **kw}


@pytest.mark.parametrize("transforms,match", [
    ({"frames": [1, 2]}, "every entry of 'frames' must be an object"),
    ({"frames": [_frame(i, file_path=7) for i in range(3)]}, "'file_path' must be a text"),
    ({"fl_x": "abc", "fl_y": 10, "cx": 8, "cy": 8, "frames": [_frame(i) for i in range(3)]}, "fl_x must be a number"),
    ({"fl_x": float("nan"), "fl_y": 10, "cx": 8, "cy": 8, "frames": [_frame(i) for i in range(3)]}, "fl_x must be a fin"),
    ({"fl_x": 10, "fl_y": 10, "cx": 8, "cy": 8, "k1": 1e300, "frames": [_frame(i) for i in range(3)]}, "k1 must be"),
    ({"fl_x": 10, "fl_y": 10, "cx": 8, "frames": [_frame(i) for i in range(3)]}, "fl_x, fl_y, cx, cy are required"),
    ({"fl_x": 10, "fl_y": 10, "cx": 8, "cy": 8, "frames": [dict(_frame(i), transform_matrix=[[1e300] * 4] * 4)
                                                            for i in range(3)]}, "finite numbers within"),
    ({"fl_x": 10, "fl_y": 10, "cx": 8, "cy": 8, "frames": [dict(_frame(i), transform_matrix=[[0] * 4] * 4)
                                                            for i in range(3)]}, "degenerate rotation")])
def test_malformed_transforms_json(tmp_path, transforms, match):
    from snapshot3d.loaders import load_scene

    with pytest.raises(UserError, match=match):
        load_scene(_capture(tmp_path, transforms))


def test_blender_camera_angle_and_downscale(tmp_path):
    from snapshot3d.loaders import load_scene

    frames = [dict(_frame(i), file_path=f"{i}") for i in range(3)]
    for angle, match in (("wide", "camera_angle_x must be a number"), (float("inf"), "camera_angle_x must be a fin")):
        _capture(tmp_path, {"camera_angle_x": angle, "frames": frames})
        (tmp_path / "transforms_train.json").write_text((tmp_path / "transforms.json").read_text())
        with pytest.raises(UserError, match=match):
            load_scene(str(tmp_path))
    with pytest.raises(UserError, match="leaves nothing"):
        load_scene(_capture(tmp_path, {"fl_x": 10, "fl_y": 10, "cx": 8, "cy": 8, "frames": [_frame(i) for i in range(3)]}),
                   downscale=1000)


# --- the command line's numbers ---

@pytest.mark.parametrize("args,match", [
    (("render", "S", "-o", "V", "--size", "100000"), "--size must be an integer in 8..2048"),
    (("render", "S", "-o", "V", "--views", "0"), "--views must be an integer in 1..360"),
    (("render", "S", "-o", "V", "--views", "360", "--size", "2048"), "over the 67 M a render holds in memory"),
    (("mesh", "S", "-o", "M.glb", "--res", "100000"), "--res must be an integer in 8..256"),
    (("decode", "P", "-o", "V", "--samples", "1000000"), "--samples must be an integer in 1..256")])
def test_cli_numbers_are_bounded(tmp_path, args, match):
    scene = str(asset("spot-print.s3d"))
    args = [scene if a == "S" else str(asset("example-photo.jpg")) if a == "P" else str(tmp_path / a) if a in ("V", "M.glb")
            else a for a in args]
    assert_one_line_error(run_cli(*args), match)
    assert not any(tmp_path.iterdir())


def test_image_readers_refuse_formats_and_sizes_from_the_header(tmp_path):
    gif = tmp_path / "a.gif"
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(gif)
    with pytest.raises(UserError, match="GIF image; give a JPEG or PNG"):
        read_image_bgr(gif)
    heic = tmp_path / "IMG_0001.HEIC"   # an iPhone's default photo: its box header, named in the message
    heic.write_bytes(b"\x00\x00\x00\x18ftypheic\x00\x00\x00\x00mif1heic" + bytes(200))
    with pytest.raises(UserError, match=r"^IMG_0001\.HEIC is a HEIF/HEIC or AVIF photo, which is not read here: save "
                                        r"it as JPEG"):
        read_image_bgr(heic)
    with pytest.raises(UserError, match="over the 120 MP limit"):
        validate.check_image_size(20000, 20000, "x.png")


def test_outputs_to_unwritable_paths_are_one_line_errors(tmp_path):
    from snapshot3d.scanner.imageio_safe import write_atomic

    write_atomic(tmp_path / "new" / "dir" / "a.json", b"{}")
    assert (tmp_path / "new" / "dir" / "a.json").read_bytes() == b"{}"
    (tmp_path / "f").write_text("x")
    for bad in (tmp_path / "new", tmp_path / "f" / "a.json"):     # a folder; a file as the folder
        with pytest.raises(UserError, match="cannot write"):
            write_atomic(bad, b"{}")
    assert sorted(p.name for p in (tmp_path / "new").iterdir()) == ["dir"]


def test_a_device_or_a_pipe_is_refused_in_one_line_without_reading_it(tmp_path):
    """/dev/zero would never end; a named pipe would block: both are refused from their type."""
    import os

    fifo = tmp_path / "photo.jpg"
    os.mkfifo(fifo)
    for cmd in (["decode", "/dev/zero", "-o", str(tmp_path / "o")], ["decode", str(fifo), "-o", str(tmp_path / "o")],
                ["render", "/dev/zero", "-o", str(tmp_path / "r")]):
        proc = run_cli(*cmd, timeout=60)
        assert proc.returncode == 1 and proc.stderr.count("\n") == 1 and "not a regular file" in proc.stderr, proc.stderr
    assert not (tmp_path / "o").exists() and not (tmp_path / "r").exists()
