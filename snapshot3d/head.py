"""A scene's own head: the shared decoder's last layer, refitted for one scene and carried as text (numpy only).

The shared decoder (`tri-dec-N`) ships in the app. Its last layer, hidden H -> (density logit, r, g, b), is the
part a scene gains most from having to itself (docs/fitting.md, "A head of the scene's own"): 4 * (H + 1)
numbers. A scene carries the difference from the shared layer as 8-bit codes with one step, in its metadata
text (the sheet's QR code, a snapshot file's text chunk) as

    h=<step>,<codes>

`step` a positive decimal (`%.4g`), `codes` the 4 * (H + 1) signed bytes (-127..127; row-major over the layer
[W | b], W (4, H), b (4,)) in URL-safe base64 without padding. The head is then

    head = shared + step * codes     (float32, (4, H + 1))

and the decoder's output is `hidden @ head[:, :H].T + head[:, H]` on the last hidden layer's activations
(the field graph's `hidden` output, `export.models.FieldGraph`)."""
from __future__ import annotations

import base64
import binascii
import math
import re

import numpy as np

from . import formats

__all__ = ["HEAD_KEY", "encode_head", "parse_head", "head_weights", "apply_head", "shared_head", "head_bytes"]

HEAD_KEY = "h"
CODE_MAX = 127
_B64 = re.compile(r"^[A-Za-z0-9_-]*$")
MAX_HIDDEN = 256   # the widest decoder a head may belong to (tri-dec-2: 64)


def head_bytes(hidden: int) -> int:
    """Bytes a head of a decoder `hidden` wide carries: one code per value and the step (float32)."""
    return 4 * (hidden + 1) + 4


def encode_head(delta: np.ndarray) -> str:
    """delta (4, H + 1) float, the scene's last layer minus the shared one -> the text `step,codes` (the value of
    the metadata's h= field). The step is the one the text states, so `parse_head` gives back the very codes."""
    delta = np.asarray(delta, np.float64)
    if delta.ndim != 2 or delta.shape[0] != 4 or not np.all(np.isfinite(delta)):
        raise ValueError(f"a head delta is (4, H + 1) and finite, got {delta.shape}")
    peak = float(np.abs(delta).max())
    step = float(f"{max(peak, 1e-6) / CODE_MAX:.4g}")
    while np.abs(delta).max() / step > CODE_MAX + 0.5:   # %.4g rounded the step down
        step = float(f"{step * 1.0001:.4g}")
    codes = np.clip(np.round(delta / step), -CODE_MAX, CODE_MAX).astype(np.int8)
    text = base64.urlsafe_b64encode(codes.tobytes()).decode("ascii").rstrip("=")
    return f"{step:.4g},{text}"


def parse_head(text: str, hidden: int | None = None) -> tuple[float, np.ndarray]:
    """The h= field's text -> (step, codes (4, H + 1) int8). ValueError (naming what is wrong) unless the step
    is a positive finite number and the codes are 4 * (H + 1) bytes in -127..127 for an H in 1..MAX_HIDDEN (the
    given `hidden`, when given)."""
    if not isinstance(text, str) or len(text) > 4 * (4 * (MAX_HIDDEN + 1)) // 3 + 32:
        raise ValueError("malformed head h= (not a short text)")
    step_text, _, b64 = text.partition(",")
    try:
        step = float(step_text)
    except ValueError:
        raise ValueError(f"malformed head h= (its step {step_text[:20]!r} is not a number)") from None
    if not (math.isfinite(step) and 0 < step < 1e3):
        raise ValueError(f"malformed head h= (its step {step_text[:20]!r} is not in (0, 1000))")
    if not _B64.match(b64):
        raise ValueError("malformed head h= (its codes are not URL-safe base64)")
    try:
        raw = base64.urlsafe_b64decode(b64 + "=" * (-len(b64) % 4))
    except (binascii.Error, ValueError):
        raise ValueError("malformed head h= (its codes are not URL-safe base64)") from None
    n = len(raw)
    if n % 4 or not 2 <= n // 4 <= MAX_HIDDEN + 1 or (hidden is not None and n != 4 * (hidden + 1)):
        want = f"4 * ({hidden} + 1)" if hidden is not None else f"4 * (H + 1), H in 1..{MAX_HIDDEN}"
        raise ValueError(f"malformed head h= ({n} codes; {want} expected)")
    codes = np.frombuffer(raw, np.int8).reshape(4, n // 4)
    if (codes == -128).any():
        raise ValueError("malformed head h= (a code of -128; codes are -127..127)")
    return step, codes.copy()


def head_weights(shared: np.ndarray, text: str) -> np.ndarray:
    """shared (4, H + 1) float32, the shared decoder's last layer [W | b] -> the scene's (4, H + 1) float32."""
    step, codes = parse_head(text, shared.shape[1] - 1)
    return (np.asarray(shared, np.float32) + np.float32(step) * codes.astype(np.float32)).astype(np.float32)


def shared_head(arrays: dict) -> np.ndarray:
    """A shared decoder's arrays (`train.field.Decoder.state_arrays`, or its .npz) -> its last layer [W | b]
    (4, H + 1) float32."""
    last = sum(1 for k in arrays if k.startswith("l") and k.endswith(".weight")) - 1
    w, b = np.asarray(arrays[f"l{last}.weight"], np.float32), np.asarray(arrays[f"l{last}.bias"], np.float32)
    return np.concatenate([w, b[:, None]], 1)


def apply_head(hidden: np.ndarray, head: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """hidden (M, H) float32, the last hidden layer's activations; head (4, H + 1) -> density logit (M,)
    (clamped at `formats.DENSITY_CLAMP`, as the field graph's) and rgb (M, 3) in [0, 1]."""
    out = hidden @ head[:, :-1].T + head[:, -1]
    logit = np.minimum(out[:, 0], np.float32(formats.DENSITY_CLAMP)).astype(np.float32)
    rgb = (1.0 / (1.0 + np.exp(-out[:, 1:4]))).astype(np.float32)
    return logit, rgb
