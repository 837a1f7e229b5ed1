"""Scene files: bit-exact round trip, quantisation, refusals."""

import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.scene import (
    Orbit,
    Scene,
    dequantize_planes,
    load_scene_file,
    quantize_planes,
    save_scene,
)


def _scene(rng, c=8, r=16, decoder=formats.DECODER_VERSION):
    return Scene(codes=rng.integers(0, 256, (3, c, r, r), dtype=np.uint8),
                 box=np.array([[-1, -0.5, -0.25], [1, 0.5, 0.75]]), orbit=Orbit(radius=3.5, target=(0.0, 0.1, 0.2)),
                 decoder_version=decoder, name="t")


def test_save_load_is_bit_exact(tmp_path, rng):
    s = _scene(rng)
    save_scene(s, tmp_path / "a.s3d")
    t = load_scene_file(tmp_path / "a.s3d")
    assert t.codes.dtype == np.uint8 and np.array_equal(t.codes, s.codes)
    assert np.array_equal(t.box, s.box) and t.orbit == s.orbit and t.name == "t"
    save_scene(t, tmp_path / "b.s3d")
    assert (tmp_path / "a.s3d").read_bytes() == (tmp_path / "b.s3d").read_bytes()
    assert not list(tmp_path.glob("*.partial"))


def test_scene_kb_counts_what_is_carried(rng):
    s = _scene(rng, c=8, r=64)
    assert s.carried_bytes() == 3 * 8 * 64 * 64 + 36
    assert abs(s.scene_kb - 98.34) < 0.01


def test_quantisation_error_is_half_a_code():
    v = np.linspace(-1, 1, 1001, dtype=np.float32)
    err = np.abs(dequantize_planes(quantize_planes(v)) - v)
    assert err.max() <= 1.0 / 255 + 1e-6
    assert quantize_planes(np.array([-3.0, 3.0])).tolist() == [0, 255]


def test_other_decoder_version_is_refused(tmp_path, rng):
    save_scene(_scene(rng, decoder="tri-dec-0"), tmp_path / "old.s3d")
    with pytest.raises(UserError, match="fitted for decoder 'tri-dec-0'"):
        load_scene_file(tmp_path / "old.s3d")


@pytest.mark.parametrize("content", [b"", b"not a zip", b"PK\x03\x04garbage"])
def test_corrupt_scene_file_is_refused(tmp_path, content):
    (tmp_path / "x.s3d").write_bytes(content)
    with pytest.raises(UserError, match="not a snapshot3d scene file"):
        load_scene_file(tmp_path / "x.s3d")


def test_truncated_scene_file_is_refused(tmp_path, rng):
    save_scene(_scene(rng), tmp_path / "a.s3d")
    data = (tmp_path / "a.s3d").read_bytes()
    (tmp_path / "t.s3d").write_bytes(data[: len(data) // 2])
    with pytest.raises(UserError, match="not a snapshot3d scene file"):
        load_scene_file(tmp_path / "t.s3d")
