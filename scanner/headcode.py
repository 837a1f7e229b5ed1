"""A scene's own head on the sheet (numpy only): two small QR codes above and below the main one
(`formats.HEAD_CODE_BOXES`), so that the main code keeps its size and its modules their width.

The head's text (the metadata's h= value, `snapshot3d.head`: `step,codes` with the codes in base64url) is
carried as `STEP:BASE45` (the step's `%.4g` text in upper case, the code bytes in RFC 9285 base45), which QR's
alphanumeric mode packs at 5.5 bits a character (base64url would need byte mode: 8 bits a character). That text
is cut in two halves, each drawn as `S3DH<i><n>:<half>` (i = 1..n, n = 2). The QR code's text then ends in
`HEAD_CODES_FIELD` (`|H=2`), which tells the scanner to read them (older builds ignore the unknown field).

The head codes use QR's error correction level L (`HEAD_CODE_LEVEL`): 33 modules a side where level M needs 37,
so each module is wider in the same 60 units. On simulated `severe` photos (spot's sheet in coffee, 12 seeds)
both codes were read from 9 photos at L against 7 at M; sheets drawn at M still read."""
from __future__ import annotations

import base64

from snapshot3d import formats

__all__ = ["HEAD_MAGIC", "HEAD_CODES_FIELD", "HEAD_CODE_LEVEL", "split_head", "join_head", "b45encode", "b45decode"]

HEAD_MAGIC = "S3DH"
HEAD_CODES_FIELD = f"H={len(formats.HEAD_CODE_BOXES)}"
HEAD_CODE_LEVEL = "L"
_B45 = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ $%*+-./:"
_B45_INDEX = {c: i for i, c in enumerate(_B45)}


def b45encode(data: bytes) -> str:
    """RFC 9285 base45: two bytes -> three characters (a last odd byte -> two)."""
    out = []
    for i in range(0, len(data) - 1, 2):
        n = data[i] * 256 + data[i + 1]
        out += [_B45[n % 45], _B45[n // 45 % 45], _B45[n // 2025]]
    if len(data) % 2:
        out += [_B45[data[-1] % 45], _B45[data[-1] // 45]]
    return "".join(out)


def b45decode(text: str) -> bytes:
    """Inverse of `b45encode`; ValueError on a character outside the alphabet, a stray character or a value
    over a byte pair's range."""
    if len(text) % 3 == 1 or any(c not in _B45_INDEX for c in text):
        raise ValueError("not base45")
    out = bytearray()
    for i in range(0, len(text), 3):
        chunk = [_B45_INDEX[c] for c in text[i:i + 3]]
        n = sum(v * 45 ** k for k, v in enumerate(chunk))
        if (len(chunk) == 3 and n > 0xFFFF) or (len(chunk) == 2 and n > 0xFF):
            raise ValueError("not base45")
        out += n.to_bytes(2, "big") if len(chunk) == 3 else bytes([n])
    return bytes(out)


def split_head(head: str, n: int = len(formats.HEAD_CODE_BOXES)) -> list[str]:
    """The h= text -> the `n` head codes' payloads (upper-case alphanumeric)."""
    step, _, b64 = head.partition(",")
    raw = base64.urlsafe_b64decode(b64 + "=" * (-len(b64) % 4))
    text = f"{step.upper()}:{b45encode(raw)}"
    cut = [round(len(text) * i / n) for i in range(n + 1)]
    return [f"{HEAD_MAGIC}{i + 1}{n}:{text[cut[i]:cut[i + 1]]}" for i in range(n)]


def join_head(parts: list[str]) -> str:
    """The head codes' payloads, in any order -> the h= text. ValueError when they are not one head's codes (a
    foreign code, a part missing or twice, a malformed text)."""
    got = {}
    for p in parts:
        if not (isinstance(p, str) and p.startswith(HEAD_MAGIC) and len(p) >= len(HEAD_MAGIC) + 3
                and p[len(HEAD_MAGIC):len(HEAD_MAGIC) + 2].isdigit() and p[len(HEAD_MAGIC) + 2] == ":"):
            raise ValueError("not a snapshot3d head code")
        i, n = int(p[len(HEAD_MAGIC)]), int(p[len(HEAD_MAGIC) + 1])
        if not 1 <= i <= n or i in got or n != len(parts):
            raise ValueError("the head codes are not one head's")
        got[i] = p[len(HEAD_MAGIC) + 3:]
    step, sep, b45 = "".join(got[i] for i in sorted(got)).partition(":")
    if not sep:
        raise ValueError("not a snapshot3d head code")
    codes = base64.urlsafe_b64encode(b45decode(b45)).decode("ascii").rstrip("=")
    return f"{step.lower()},{codes}"
