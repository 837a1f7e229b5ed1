"""Property-based tests of the readers of outside data (hypothesis, derandomized: the same examples every
run). Each reader, on generated or mutated input, either returns what it promises with every number finite
or raises `UserError` (ValueError where its contract says so); nothing else escapes."""
import io
import math
import struct
import zlib

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image, PngImagePlugin

from snapshot3d import formats, validate
from snapshot3d.codecs.media import CODEC_MEDIUM
from snapshot3d.errors import UserError
from snapshot3d.paths import asset
from snapshot3d.scanner.imageio_safe import image_size, read_image_bgr
from snapshot3d.scanner.pixelmeta import unpack
from snapshot3d.scanner.qr import SheetMeta, check_meta, decode_payload
from snapshot3d.scanner.snapfile import metadata_text
from snapshot3d.scene import load_scene_file

SETTINGS = dict(derandomize=True, database=None, deadline=None, suppress_health_check=list(HealthCheck))
SCENE = asset("spot-print.s3d").read_bytes()


def _finite_meta(meta: SheetMeta) -> None:
    for f in (meta.box, meta.orbit, meta.target, meta.planes):
        assert f is None or all(math.isfinite(v) for v in f)
    assert meta.strength is None or math.isfinite(meta.strength)


_NUMBER = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(lambda x: f"{x!r}"),
                    st.integers(-70000, 70000).map(str), st.sampled_from(["1e309", "-1e309", "nan", "", "1_0", "0x10",
                                                                          " 3 ", "1e-300", "4.202", "40", "64"]),
                    st.text(max_size=6))
_FIELD = st.tuples(st.sampled_from("botpsxq"), st.lists(_NUMBER, min_size=0, max_size=7)).map(
    lambda kv: f"{kv[0]}={','.join(kv[1])}")


@settings(max_examples=250, **SETTINGS)
@given(codec=st.sampled_from(list(CODEC_MEDIUM) + ["", "x" * 40, "hinet-9"]),
       version=st.sampled_from(["1", "2", "", "01", "9" * 10]), fields=st.lists(_FIELD, max_size=7))
def test_metadata_parser_raises_only_its_errors_and_returns_finite_numbers(codec, version, fields):
    text = "|".join([formats.QR_MAGIC + version, codec, *fields])
    try:
        meta = check_meta(decode_payload(text))
    except (ValueError, UserError) as e:
        assert "\n" not in str(e)
        return
    _finite_meta(meta)
    if meta.planes is not None:
        assert 2 <= meta.planes[0] <= formats.CODEC_MAX_RES and 1 <= meta.planes[1] <= formats.C_MAX
    if meta.orbit is not None:
        assert meta.orbit[0] > 0 and validate.FOV_RANGE[0] <= meta.orbit[2] <= validate.FOV_RANGE[1]


@settings(max_examples=120, **SETTINGS)
@given(body=st.binary(min_size=34, max_size=34), version=st.sampled_from([1, 2]))
def test_pixel_mark_frames_with_a_valid_crc_read_as_checked_metadata_or_error(body, version):
    """A hostile mark can carry any bytes with a valid CRC (float16 infinities, NaNs, huge plane sizes)."""
    nbytes = 38 if version == 2 else 72
    body = bytes([version]) + (body * 3)[:nbytes - 5]
    meta = unpack(body + struct.pack("<I", zlib.crc32(body)))
    if meta is None:
        return
    try:
        _finite_meta(check_meta(meta))
    except UserError as e:
        assert "\n" not in str(e)


_MUTATION = st.lists(st.tuples(st.integers(0, len(SCENE) - 1), st.integers(0, 255)), min_size=1, max_size=6)


@settings(max_examples=200, **SETTINGS)
@given(mutation=_MUTATION, cut=st.one_of(st.none(), st.integers(0, len(SCENE))))
def test_scene_reader_on_mutated_bytes_gives_a_finite_scene_or_a_user_error(tmp_path_factory, mutation, cut):
    data = bytearray(SCENE)
    for i, b in mutation:
        data[i] = b
    path = tmp_path_factory.getbasetemp() / "mutated.s3d"
    path.write_bytes(bytes(data[:cut]))
    try:
        scene = load_scene_file(path)
    except UserError as e:
        assert "\n" not in str(e)
        return
    assert scene.codes.dtype == np.uint8 and scene.codes.shape[0] == 3
    assert np.isfinite(scene.box).all() and np.all(scene.box[1] > scene.box[0])
    o = scene.orbit
    assert all(math.isfinite(v) for v in (o.radius, o.elevation_deg, o.fov_deg, *o.target)) and o.radius > 0


def _small_image_files() -> dict[str, bytes]:
    rgb = (np.random.default_rng(1).random((48, 64, 3)) * 255).astype(np.uint8)
    text = "S3D1|hinet-3|b=-1,-1,-1,1,1,1|o=4,20,40|t=0,0,0|p=64,8|s=1"
    png, jpg = io.BytesIO(), io.BytesIO()
    info = PngImagePlugin.PngInfo()
    info.add_text("snapshot3d", text)
    Image.fromarray(rgb).save(png, format="PNG", pnginfo=info)
    Image.fromarray(rgb).save(jpg, format="JPEG", quality=80, comment=text.encode())
    return {".png": png.getvalue(), ".jpg": jpg.getvalue(), ".bmp": cv2.imencode(".bmp", rgb)[1].tobytes()}


FILES = _small_image_files()


@settings(max_examples=200, **SETTINGS)
@given(ext=st.sampled_from(sorted(FILES)), data=st.data())
def test_image_reader_on_mutated_bytes_gives_an_image_or_a_user_error(tmp_path_factory, ext, data):
    raw = bytearray(FILES[ext])
    mutation = data.draw(st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(0, 255)), min_size=1, max_size=8))
    for i, b in mutation:
        raw[i] = b
    cut = data.draw(st.one_of(st.none(), st.integers(0, len(raw))))
    path = tmp_path_factory.getbasetemp() / f"mutated{ext}"
    path.write_bytes(bytes(raw[:cut]))
    try:
        img = read_image_bgr(path)
    except UserError as e:
        assert "\n" not in str(e)
        return
    w, h, _ = image_size(path)   # a changed header may declare another size: the decoder must agree with it
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3 and sorted(img.shape[:2]) == sorted((w, h))
    assert w * h <= validate.MAX_PIXELS
    text = metadata_text(path)
    if text is not None:
        try:
            _finite_meta(check_meta(decode_payload(text)))
        except (ValueError, UserError) as e:
            assert "\n" not in str(e)


@settings(max_examples=150, **SETTINGS)
@given(value=st.one_of(st.floats(), st.integers(-10 ** 400, 10 ** 400), st.text(max_size=4), st.booleans(),
                       st.none(), st.lists(st.floats(), max_size=3)),
       lo=st.floats(-1e6, 0), hi=st.floats(0, 1e6))
def test_validate_number_and_integer(value, lo, hi):
    try:
        x = validate.number(value, "x", lo, hi)
        assert math.isfinite(x) and lo <= x <= hi
    except UserError as e:
        assert str(e).startswith("x must be")
    try:
        n = validate.integer(value, "n", -5, 5)
        assert isinstance(n, int) and -5 <= n <= 5
    except UserError as e:
        assert str(e).startswith("n must be an integer in -5..5")


@pytest.mark.parametrize("box", [np.array([[-1, -1, -1], [1, 1, 1]], np.float32), [[0, 0, 0], [1, 2, 3]],
                                 (0, 0, 0, 1, 2, 3)])
def test_check_box_accepts_each_layout(box):
    out = validate.check_box(box)
    assert out.shape == (2, 3) and out.dtype == np.float32
