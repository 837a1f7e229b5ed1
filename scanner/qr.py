"""The sheet's QR code: payload text <-> metadata, and drawing/reading it with OpenCV 5.

Payload (`formats` QR_*): "S3D<version>|<codec id>[|b=x0,y0,z0,x1,y1,z1][|o=radius,elevation,fov]
[|t=x,y,z][|p=R,C][|s=strength][|d=N][|h=step,codes]" (orbit target, plane resolution and channels, embedding
strength, shared decoder `tri-dec-N`: absent on sheets of `tri-dec-1` scenes, which older builds made; the scene's
own head, `snapshot3d.head`: absent where the scene uses the shared decoder's last layer).
The same text travels in a snapshot file's metadata (PNG text chunk or JPEG comment)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from snapshot3d import formats, validate
from snapshot3d.codecs.media import CODEC_MEDIUM, MEDIA
from snapshot3d.errors import UserError
from snapshot3d.head import HEAD_KEY, parse_head

__all__ = ["SheetMeta", "encode_payload", "decode_payload", "qr_matrix", "read_qr", "check_codec", "check_meta",
           "scene_meta", "MAX_PAYLOAD"]


@dataclass(frozen=True)
class SheetMeta:
    """What decoding needs to know about a sheet."""

    version: int = formats.SHEET_FORMAT_VERSION
    """sheet format version"""
    codec: str = MEDIA[formats.DEFAULT_MEDIUM].codec
    """id of the codec that made the snapshot (`codecs.media.CODEC_MEDIUM` names its medium)"""
    box: tuple | None = None
    """scene box (x0, y0, z0, x1, y1, z1) in world units, or None"""
    orbit: tuple | None = None
    """default orbit (radius, elevation_deg, fov_deg), or None"""
    target: tuple | None = None
    """orbit target (x, y, z), or None (the box centre)"""
    planes: tuple | None = None
    """(R, C) of the hidden planes, or None"""
    strength: float | None = None
    """embedding strength the snapshot was made with, or None (1)"""
    decoder: int | None = None
    """N of the shared decoder `tri-dec-N` the scene was fitted for, or None (1: older sheets)"""
    head: str | None = None
    """the scene's own head, the h= field's text `step,codes` (`snapshot3d.head`), or None (the shared one)"""

    @property
    def decoder_version(self) -> str:
        return f"tri-dec-{1 if self.decoder is None else self.decoder}"

    def as_dict(self) -> dict:
        return {"version": self.version, "codec": self.codec,
                "box": list(self.box) if self.box else None, "orbit": list(self.orbit) if self.orbit else None,
                "target": list(self.target) if self.target else None,
                "planes": list(self.planes) if self.planes else None, "strength": self.strength,
                "decoder": self.decoder, "head": self.head}


def _nums(values) -> str:
    return ",".join(f"{float(v):.4g}" for v in values)


def encode_payload(meta: SheetMeta) -> str:
    parts = [f"{formats.QR_MAGIC}{meta.version}", meta.codec]
    if meta.box is not None:
        parts.append("b=" + _nums(meta.box))
    if meta.orbit is not None:
        parts.append("o=" + _nums(meta.orbit))
    if meta.target is not None:
        parts.append("t=" + _nums(meta.target))
    if meta.planes is not None:
        parts.append("p=" + ",".join(str(int(v)) for v in meta.planes))
    if meta.strength is not None:
        parts.append("s=" + _nums([meta.strength]))
    if meta.decoder is not None:
        parts.append(f"d={int(meta.decoder)}")
    if meta.head is not None:
        parts.append(f"{HEAD_KEY}={meta.head}")
    text = formats.QR_SEP.join(parts)
    if any(formats.QR_SEP in p for p in parts[1:2]):
        raise ValueError(f"codec id must not contain {formats.QR_SEP!r}")
    return text


MAX_PAYLOAD = 512
"""characters of a metadata text (a QR code of the sheet holds about 100; longer text is refused unread)"""
_LENGTHS = {"b": 6, "o": 3, "t": 3, "p": 2, "s": 1, "d": 1}


def decode_payload(text: str) -> SheetMeta:
    """Parse a payload; raises ValueError when it is not a snapshot3d sheet's, or a field is malformed (a
    known field with the wrong count of numbers, or a number that is not finite). Unknown fields are
    ignored. The numbers' ranges are checked by `check_meta`."""
    if not isinstance(text, str) or len(text) > MAX_PAYLOAD:
        raise ValueError(f"not a snapshot3d QR payload (over {MAX_PAYLOAD} characters)")
    parts = text.split(formats.QR_SEP)
    version = parts[0][len(formats.QR_MAGIC):]
    if len(parts) < 2 or not parts[0].startswith(formats.QR_MAGIC) or not (version.isascii() and version.isdigit()
                                                                           and len(version) <= 6):
        raise ValueError(f"not a snapshot3d QR payload: {text[:40]!r}")
    fields, head = {}, None
    for p in parts[2:]:
        key, _, val = p.partition("=")
        if key == HEAD_KEY:
            parse_head(val)   # ValueError naming what is malformed
            head = val
            continue
        if key not in _LENGTHS:
            continue
        try:
            nums = tuple(float(v) for v in val.split(","))
        except ValueError:
            raise ValueError(f"malformed number in QR payload field {key}=: {text[:60]!r}") from None
        if len(nums) != _LENGTHS[key]:
            raise ValueError(f"malformed field {key}= in QR payload ({_LENGTHS[key]} numbers expected): "
                             f"{text[:60]!r}")
        if not all(math.isfinite(v) for v in nums):
            raise ValueError(f"malformed field {key}= in QR payload (a number that is not finite): {text[:60]!r}")
        fields[key] = nums
    planes = None
    if "p" in fields:
        if not all(v.is_integer() and 0 <= v < 1 << 16 for v in fields["p"]):
            raise ValueError(f"malformed field p= in QR payload (two integers in 0..65535 expected): {text[:60]!r}")
        planes = tuple(int(v) for v in fields["p"])
    strength = fields["s"][0] if "s" in fields else None
    decoder = None
    if "d" in fields:
        if not (fields["d"][0].is_integer() and 0 <= fields["d"][0] < 1 << 16):
            raise ValueError(f"malformed field d= in QR payload (an integer in 0..65535 expected): {text[:60]!r}")
        decoder = int(fields["d"][0])
    return SheetMeta(int(version), parts[1], fields.get("b"), fields.get("o"), fields.get("t"), planes, strength,
                     decoder, head)


def check_meta(meta: SheetMeta, where: str = "the snapshot's metadata", require_codec: bool = True,
               chart: bool = False) -> SheetMeta:
    """UserError (one line, naming the field and its allowed range) unless every field of `meta` is usable:
    a sheet format and codec this build reads (`check_codec`; without `require_codec` an unknown one is left
    to the caller), a plane size the codec carries, a box, orbit and target within `snapshot3d.validate`'s
    bounds, a strength in its range. Fields that are None are not required here. `chart`: the calibration
    chart's codec passes (`check_codec`). Returns `meta`."""
    if require_codec:
        check_codec(meta, chart)
    if meta.planes is not None and meta.codec in CODEC_MEDIUM:
        from snapshot3d.codecs.media import medium_of

        res, channels = meta.planes
        error = medium_of(meta.codec).plane_error(channels, res)
        if error:
            raise UserError(f"{where}: plane size p={res},{channels} is out of range for codec {meta.codec} ({error})")
    if meta.box is not None:
        validate.check_box(meta.box, f"{where}: box b=")
    if meta.orbit is not None:
        validate.check_orbit(*meta.orbit, field=f"{where}: orbit o=")
    if meta.target is not None:
        validate.numbers(meta.target, f"{where}: target t=", 3, -validate.WORLD_LIMIT, validate.WORLD_LIMIT)
    if meta.strength is not None:
        validate.number(meta.strength, f"{where}: strength s=", *validate.STRENGTH_RANGE)
    if meta.decoder_version not in formats.DECODERS:
        raise UserError(f"{where}: the scene was fitted for decoder {meta.decoder_version} (d={meta.decoder}), but "
                        f"this build has decoder {', '.join(formats.DECODERS)}; update snapshot3d")
    return meta


def qr_matrix(text: str, level: str = "M") -> np.ndarray:
    """(N, N) uint8 QR modules for `text` (255 white, 0 black), quiet zone removed; error correction `level`
    (L, M, Q or H)."""
    params = cv2.QRCodeEncoder.Params()
    params.correction_level = getattr(cv2, f"QRCodeEncoder_CORRECT_LEVEL_{level}")
    q = cv2.QRCodeEncoder.create(params).encode(text)
    dark = np.argwhere(q == 0)
    (r0, c0), (r1, c1) = dark.min(0), dark.max(0)
    return np.ascontiguousarray(q[r0:r1 + 1, c0:c1 + 1])


def read_qr(gray: np.ndarray) -> str | None:
    """Decode a QR code from (H, W) uint8 grey (a fronto-parallel crop with a quiet zone); None if unreadable."""
    det = cv2.QRCodeDetector()

    def variants():  # cheapest first; the later ones only run when the earlier fail
        yield gray
        yield cv2.GaussianBlur(gray, (0, 0), 1.0)
        soft = cv2.GaussianBlur(gray, (0, 0), 2.0)
        yield cv2.addWeighted(gray, 2.5, soft, -1.5, 0)  # unsharp mask against blur
        yield cv2.adaptiveThreshold(gray, 255, cv2.ADAPTIVE_THRESH_GAUSSIAN_C, cv2.THRESH_BINARY, 31, 0)

    for img in variants():
        text, _, _ = det.detectAndDecode(img)
        if text:
            return text
    return None


def check_codec(meta: SheetMeta, chart: bool = False) -> None:
    """UserError when the snapshot was made for another sheet format or a codec this build does not have.
    The calibration chart's codec id (`formats.CALIB_CODEC`) passes only with `chart` (`snapshot3d calibrate`
    scans the chart as `scan` scans a sheet); elsewhere it is refused with a line naming `calibrate`."""
    if meta.version != formats.SHEET_FORMAT_VERSION:
        raise UserError(f"sheet format version {meta.version} is not supported (this build reads "
                        f"version {formats.SHEET_FORMAT_VERSION})")
    if meta.codec == formats.CALIB_CODEC and not chart:
        raise UserError("this is a snapshot3d calibration chart, not a snapshot: measure the printer and phone with "
                        "'snapshot3d calibrate PHOTO'")
    if meta.codec not in CODEC_MEDIUM and not (meta.codec == formats.CALIB_CODEC and chart):
        known = ", ".join(f"{c} ({m})" for c, m in CODEC_MEDIUM.items())
        raise UserError(f"unknown codec id {validate.show(meta.codec)} in the snapshot's metadata or QR code: this build decodes "
                        f"{known}")


def scene_meta(scene, codec: str = MEDIA[formats.DEFAULT_MEDIUM].codec, strength: float | None = 1.0) -> SheetMeta:
    """What a snapshot of `scene` (`snapshot3d.scene.Scene`) made with `codec` carries as metadata: box,
    orbit, plane size, embedding strength, decoder version and the scene's own head."""
    o = scene.orbit
    return SheetMeta(codec=codec, box=tuple(float(v) for v in np.asarray(scene.box).ravel()),
                     orbit=(float(o.radius), float(o.elevation_deg), float(o.fov_deg)),
                     target=tuple(float(v) for v in o.target), planes=(scene.resolution, scene.channels),
                     strength=None if strength is None else float(strength),
                     decoder=_decoder_field(scene.decoder_version), head=getattr(scene, "head", None))


def _decoder_field(version: str) -> int | None:
    """The d= field of a scene fitted for `version`: None for tri-dec-1 (sheets as older builds made them)."""
    n = formats.decoder_number(version)
    if n is None:
        raise ValueError(f"decoder version {version!r} is not of the form tri-dec-N")
    return None if n == 1 else n
