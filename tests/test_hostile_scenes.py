"""Hostile scene files (issue 36, classes 5 to 8): headers of the wrong JSON type, .npy headers that np.load
rejects with the parser's own exceptions, bombs declared in a small file, non-finite or degenerate numbers.
Each is refused from the zip directory and the .npy headers, before anything is allocated."""
import io
import json
import zipfile

import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli

from snapshot3d import formats, validate
from snapshot3d.errors import UserError
from snapshot3d.scene import Orbit, Scene, load_scene_file, save_scene


def _npy(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, arr, allow_pickle=False)
    return buf.getvalue()


def _npy_declaring(shape, descr="|u1", data=b"") -> bytes:
    """A .npy whose header declares `shape` and whose data is `data` (a bomb: a small file, a huge shape)."""
    head = repr({"descr": descr, "fortran_order": False, "shape": tuple(shape)}).encode()
    head += b" " * (63 - (len(head) + 10) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(head).to_bytes(2, "little") + head + data


def _header(**kw):
    h = {"format_version": formats.SCENE_FORMAT_VERSION, "decoder_version": formats.DECODER_VERSION,
         "name": "x", "orbit": {"radius": 3.0, "elevation_deg": 20.0, "fov_deg": 40.0, "target": [0, 0, 0]},
         "meta": {}}
    h.update(kw)
    return np.frombuffer(json.dumps(h).encode(), np.uint8)


def _s3d(path, codes=None, box=None, header=None, raw: dict | None = None):
    members = {"codes.npy": _npy(np.zeros((3, 4, 16, 16), np.uint8) if codes is None else codes),
               "box.npy": _npy(np.array([[-1, -1, -1], [1, 1, 1]], np.float32) if box is None else box),
               "header.npy": _npy(_header() if header is None else header)}
    members.update(raw or {})
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def test_a_well_formed_crafted_scene_loads(tmp_path):
    s = load_scene_file(_s3d(tmp_path / "ok.s3d"))
    assert s.codes.shape == (3, 4, 16, 16) and s.orbit.radius == 3.0 and s.box.dtype == np.float32


@pytest.mark.parametrize("header,match", [
    (json.dumps([1, 2]), "must be a JSON object, got list"), (json.dumps("x"), "got str"),
    ("null", "got NoneType"), ("{", "JSONDecodeError"), ("\xff", "UnicodeDecodeError"),
    ("[" * 5000 + "]" * 5000, "RecursionError|got list")])
def test_scene_header_that_is_not_an_object(tmp_path, header, match):
    data = np.frombuffer(header.encode("latin-1"), np.uint8)
    with pytest.raises(UserError, match=match):
        load_scene_file(_s3d(tmp_path / "h.s3d", header=data))


@pytest.mark.parametrize("orbit", [[1, 2, 3], None, "far", {"radius": "3"}, {"radius": True},
                                   {"radius": 3, "target": [0, 0]}, {"radius": 3, "zoom": 2}, {}])
def test_scene_orbit_of_the_wrong_type(tmp_path, orbit):
    with pytest.raises(UserError, match="orbit"):
        load_scene_file(_s3d(tmp_path / "o.s3d", header=_header(orbit=orbit)))


@pytest.mark.parametrize("field,value,match", [
    ("radius", 0, "radius"), ("radius", -1, "radius"), ("radius", float("nan"), "radius"),
    ("radius", 10 ** 400, "radius"), ("fov_deg", 0, "fov_deg"), ("fov_deg", 180, "fov_deg"),
    ("fov_deg", 1e9, "fov_deg"), ("elevation_deg", float("inf"), "elevation_deg")])
def test_scene_orbit_out_of_range(tmp_path, field, value, match):
    orbit = {"radius": 3.0, "elevation_deg": 20.0, "fov_deg": 40.0, "target": [0, 0, 0], field: value}
    with pytest.raises(UserError, match=rf"orbit {match} must be a finite number in"):
        load_scene_file(_s3d(tmp_path / "o.s3d", header=_header(orbit=orbit)))


@pytest.mark.parametrize("box", [[[np.nan, 0, 0], [1, 1, 1]], [[0, 0, 0], [np.inf, 1, 1]], [[1, 1, 1], [0, 0, 0]],
                                 [[0, 0, 0], [1, 1, 0]], [[0, 0, 0], [1e6, 1, 1]]])
def test_scene_box_nan_inf_inverted_or_flat(tmp_path, box):
    with pytest.raises(UserError, match="box"):
        load_scene_file(_s3d(tmp_path / "b.s3d", box=np.array(box, np.float32)))


def test_saving_a_degenerate_scene_is_refused_and_leaves_nothing(tmp_path):
    codes = np.zeros((3, 4, 16, 16), np.uint8)
    for box, orbit in ((np.array([[0, 0, 0], [np.nan, 1, 1]]), Orbit(3.0)), (np.array([[0, 0, 0], [1, 1, 1]]), Orbit(-1.0))):
        with pytest.raises(UserError, match="box|radius"):
            save_scene(Scene(codes=codes, box=box, orbit=orbit), tmp_path / "s.s3d")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("shape", [(3, 12, 4096, 4096), (3, 4, 0, 0), (3, 13, 16, 16), (3, 4, 16, 8),
                                   (2, 4, 16, 16), (3, 4, 16), (3, 12, 1 << 20, 1 << 20)])
def test_scene_bombs_are_refused_from_the_header(tmp_path, shape):
    path = _s3d(tmp_path / "bomb.s3d", raw={"codes.npy": _npy_declaring(shape, data=bytes(64))})
    assert path.stat().st_size < 4096
    with pytest.raises(UserError, match=r"array 'codes' is .*allowed: \(3, C, R, R\) uint8"):
        load_scene_file(path)


def test_scene_array_of_another_dtype_or_truncated(tmp_path):
    with pytest.raises(UserError, match="array 'codes' is"):
        load_scene_file(_s3d(tmp_path / "a.s3d", raw={"codes.npy": _npy_declaring((3, 4, 16, 16), "<f8")}))
    with pytest.raises(UserError, match="declares 3072 bytes of data but the file holds 64"):
        load_scene_file(_s3d(tmp_path / "b.s3d", raw={"codes.npy": _npy_declaring((3, 4, 16, 16), data=bytes(64))}))
    with pytest.raises(UserError, match="'box' is"):
        load_scene_file(_s3d(tmp_path / "c.s3d", box=np.zeros((1 << 16,), np.float32)))


def test_every_byte_change_in_the_npy_headers_loads_or_is_a_user_error(tmp_path):
    """A flipped byte in a .npy header once raised tokenize's TokenError (or a MemoryError) through np.load."""
    good = _s3d(tmp_path / "good.s3d").read_bytes()
    starts = [i for i in range(len(good)) if good.startswith(b"\x93NUMPY", i)]
    outcomes = {"ok": 0, "user": 0}
    path = tmp_path / "m.s3d"
    for s in starts:
        for i in range(s, s + 128, 3):
            for value in (0x00, ord("'"), ord("("), 0xFF):
                data = bytearray(good)
                data[i] = value
                path.write_bytes(bytes(data))
                try:
                    load_scene_file(path)
                    outcomes["ok"] += 1
                except UserError as e:
                    assert "\n" not in str(e)
                    outcomes["user"] += 1
    assert outcomes["user"] > 300


def _patch_central(data: bytes, offset: int, value: bytes) -> bytes:
    """Change a field (`offset` into each central directory record) of every member of a zip."""
    out = bytearray(data)
    i = out.find(b"PK\x01\x02")
    while i >= 0:
        out[i + offset:i + offset + len(value)] = value
        i = out.find(b"PK\x01\x02", i + 4)
    return bytes(out)


@pytest.mark.parametrize("offset,value,name", [(6, (99).to_bytes(2, "little"), "NotImplementedError"),
                                               (10, (99).to_bytes(2, "little"), "NotImplementedError"),
                                               (16, b"\0\0\0\0", "BadZipFile")])
def test_unknown_zip_version_or_method_or_bad_crc(tmp_path, offset, value, name):
    path = _s3d(tmp_path / "z.s3d")
    path.write_bytes(_patch_central(path.read_bytes(), offset, value))
    with pytest.raises(UserError, match=f"not a snapshot3d scene file \\({name}\\)"):
        load_scene_file(path)


def test_compressed_member_bomb_is_bounded_by_the_declared_shape(tmp_path):
    path = tmp_path / "deflate.s3d"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("codes.npy", _npy_declaring((3, 4, 16, 16), data=bytes(20_000_000)))
        z.writestr("box.npy", _npy(np.array([[-1, -1, -1], [1, 1, 1]], np.float32)))
        z.writestr("header.npy", _npy(_header()))
    assert path.stat().st_size < 100_000
    with pytest.raises(UserError, match="declares 3072 bytes"):
        load_scene_file(path)


def test_oversized_scene_file_is_refused_before_reading(tmp_path):
    path = tmp_path / "big.s3d"
    with open(path, "wb") as f:
        f.truncate(validate.SCENE_MAX_BYTES + 1)
    with pytest.raises(UserError, match="larger than any scene file"):
        load_scene_file(path)


def test_cli_render_and_mesh_refuse_hostile_scene_files_in_one_line(tmp_path):
    nan_box = _s3d(tmp_path / "nan.s3d", box=np.array([[np.nan, 0, 0], [1, 1, 1]], np.float32))
    assert_one_line_error(run_cli("render", str(nan_box), "-o", str(tmp_path / "v")), "box[0] must be a finite")
    bomb = _s3d(tmp_path / "bomb.s3d", raw={"codes.npy": _npy_declaring((3, 12, 4096, 4096), data=bytes(64))})
    assert_one_line_error(run_cli("mesh", str(bomb), "-o", str(tmp_path / "m.glb")), "allowed: (3, C, R, R)")
    assert not (tmp_path / "v").exists() and not (tmp_path / "m.glb").exists()


def test_save_scene_makes_its_folder_and_refuses_an_unwritable_path(tmp_path):
    scene = Scene(codes=np.zeros((3, 4, 16, 16), np.uint8), box=np.array([[-1, -1, -1], [1, 1, 1]]), orbit=Orbit(3.0))
    save_scene(scene, tmp_path / "missing" / "dir" / "out.s3d")
    assert load_scene_file(tmp_path / "missing" / "dir" / "out.s3d").orbit.radius == 3.0
    (tmp_path / "file").write_text("x")
    with pytest.raises(UserError, match="cannot write .*out.s3d"):
        save_scene(scene, tmp_path / "file" / "out.s3d")
