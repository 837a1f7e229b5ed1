"""A scene's own head: its text round trip, refusals, the runtime's maths, and where it travels (metadata, scene
file)."""

import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.head import CODE_MAX, apply_head, encode_head, head_bytes, head_weights, parse_head
from snapshot3d.scanner.qr import SheetMeta, check_meta, decode_payload, encode_payload
from snapshot3d.scene import Orbit, Scene, load_scene_file, save_scene


def test_head_text_round_trip_is_within_half_a_step(rng):
    delta = rng.normal(0, 0.05, (4, 33))
    text = encode_head(delta)
    step, codes = parse_head(text, 32)
    assert codes.shape == (4, 33) and codes.dtype == np.int8 and np.abs(codes).max() == CODE_MAX
    assert np.abs(codes * step - delta).max() <= step / 2 + 1e-12
    assert encode_head(codes * step) == text   # the codes come back as they were
    shared = rng.normal(0, 1, (4, 33)).astype(np.float32)
    assert np.allclose(head_weights(shared, text), shared + delta, atol=step / 2 + 1e-6)
    assert head_bytes(32) == 136


@pytest.mark.parametrize("text, why", [
    ("", "not a number"), ("abc,AAAA", "not a number"), ("0,AAAAAAAA", "not in (0, 1000)"),
    ("nan,AAAAAAAA", "not in (0, 1000)"), ("0.1,AA=A", "not URL-safe base64"), ("0.1,AAA", "codes; 4 * (H + 1)"),
    ("0.1," + "A" * 20000, "not a short text"), ("0.1,gICAgICAgIA", "-128")])
def test_malformed_head_text_is_refused_naming_why(text, why):
    with pytest.raises(ValueError, match="malformed head") as e:
        parse_head(text)
    assert why in str(e.value)


def test_head_of_another_width_is_refused(rng):
    with pytest.raises(ValueError, match=r"4 \* \(32 \+ 1\) expected"):
        parse_head(encode_head(rng.normal(0, 0.1, (4, 65))), 32)


def test_apply_head_is_the_last_layer_and_its_activations(rng):
    hidden = rng.uniform(0, 2, (50, 8)).astype(np.float32)
    head = rng.normal(0, 3, (4, 9)).astype(np.float32)
    logit, rgb = apply_head(hidden, head)
    out = hidden.astype(np.float64) @ head[:, :8].T + head[:, 8]
    assert np.allclose(logit, np.minimum(out[:, 0], formats.DENSITY_CLAMP), atol=1e-4)
    assert np.allclose(rgb, 1 / (1 + np.exp(-out[:, 1:])), atol=1e-6) and logit.max() <= formats.DENSITY_CLAMP


def test_metadata_carries_the_head_and_refuses_a_malformed_one(rng):
    text = encode_head(rng.normal(0, 0.05, (4, 33)))
    meta = SheetMeta(codec=formats.PRINT_CODEC, box=(-1, -1, -1, 1, 1, 1), orbit=(3.0, 20.0, 40.0), planes=(16, 4),
                     head=text)
    payload = encode_payload(meta)
    assert payload.endswith("|h=" + text)
    back = decode_payload(payload)
    assert back.head == text and check_meta(back) == back
    assert decode_payload(encode_payload(SheetMeta())).head is None   # absent: the shared decoder's
    with pytest.raises(ValueError, match="malformed head"):
        decode_payload(payload[:-3] + "!!!")


def test_scene_file_keeps_the_head_and_counts_its_bytes(tmp_path, rng):
    text = encode_head(rng.normal(0, 0.05, (4, 33)))
    scene = Scene(codes=rng.integers(0, 256, (3, 4, 16, 16), dtype=np.uint8), box=np.array([[-1, -1, -1], [1, 1, 1]]),
                  orbit=Orbit(radius=3.0), head=text)
    save_scene(scene, tmp_path / "h.s3d")
    back = load_scene_file(tmp_path / "h.s3d")
    assert back.head == text and back.carried_bytes() == 3 * 4 * 16 * 16 + 36 + 136
    plain = Scene(codes=scene.codes, box=scene.box, orbit=scene.orbit)
    save_scene(plain, tmp_path / "p.s3d")
    assert load_scene_file(tmp_path / "p.s3d").head is None


def test_scene_file_with_a_malformed_head_is_refused_in_one_line(tmp_path, rng):
    text = encode_head(rng.normal(0, 0.05, (4, 33)))
    scene = Scene(codes=rng.integers(0, 256, (3, 4, 16, 16), dtype=np.uint8), box=np.array([[-1, -1, -1], [1, 1, 1]]),
                  orbit=Orbit(radius=3.0), head=text)
    save_scene(scene, tmp_path / "h.s3d")
    header = np.load(tmp_path / "h.s3d")["header"].tobytes().decode()
    bad = header.replace(text, "-1," + text.partition(",")[2])
    assert bad != header
    with open(tmp_path / "bad.s3d", "wb") as f:
        np.savez(f, codes=scene.codes, box=scene.box, header=np.frombuffer(bad.encode(), np.uint8))
    with pytest.raises(UserError, match=r"bad.s3d: header malformed head h= \(its step '-1' is not in"):
        load_scene_file(tmp_path / "bad.s3d")


def test_head_codes_round_trip_and_refuse_foreign_parts(rng):
    from snapshot3d.scanner.headcode import b45decode, b45encode, join_head, split_head
    for n in (0, 1, 2, 3, 133):
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert b45decode(b45encode(data)) == data
    assert b45encode(b"ietf!") == "QED8WEX0"   # RFC 9285's example
    text = encode_head(rng.normal(0, 0.05, (4, 33)))
    parts = split_head(text)
    assert len(parts) == 2 and all(p.isupper() or not any(c.isalpha() for c in p) for p in parts)
    assert join_head(parts) == text and join_head(parts[::-1]) == text
    from snapshot3d.scanner.headcode import HEAD_CODE_LEVEL
    from snapshot3d.scanner.qr import qr_matrix
    # tri-dec-1's head in two codes of 33 modules (level L): their modules 1.8 units wide in 60 (37 at level M)
    assert [qr_matrix(p, HEAD_CODE_LEVEL).shape for p in parts] == [(33, 33)] * 2
    for bad in ([parts[0]], [parts[0], parts[0]], [parts[0], "S3D1|print-2"], [parts[0], parts[1][:-1] + "~"]):
        with pytest.raises(ValueError):
            join_head(bad)


def _head_sheet_photo(meta, damage: bool = False):
    import cv2

    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.scanner.simulate import simulate
    rng = np.random.default_rng(1)
    snap = cv2.GaussianBlur((rng.random((380, 380, 3)) * 255).astype(np.uint8), (0, 0), 3)
    sheet = render_sheet(snap, meta, 2)
    if damage:   # ink over the middle of the lower head code
        x0, y0, x1, y1 = formats.HEAD_CODE_BOXES[1]
        sx0, sy0 = formats.SHEET_BOX[:2]
        sheet[(y0 + 20 - sy0) * 2:(y1 - 20 - sy0) * 2, (x0 + 10 - sx0) * 2:(x1 - 10 - sx0) * 2] = 0
    data, _, _ = simulate(sheet, "mild", 0)
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)


def test_a_photo_of_a_sheet_gives_back_the_scenes_own_head(rng):
    from snapshot3d.scanner.scan import scan_image
    text = encode_head(rng.normal(0, 0.05, (4, 33)))
    meta = SheetMeta(codec=formats.PRINT_CODEC, box=(-1, -1, -1, 1, 1, 1), orbit=(3.0, 20.0, 40.0), planes=(16, 4))
    assert scan_image(_head_sheet_photo(meta)).qr["head"] is None   # no head codes: the shared decoder's
    from dataclasses import replace
    assert scan_image(_head_sheet_photo(replace(meta, head=text))).qr["head"] == text
    qr = scan_image(_head_sheet_photo(replace(meta, head=text), damage=True)).qr   # read, without its head
    assert qr["head"] is None and qr["head_codes"] == "unread" and qr["planes"] == [16, 4]
