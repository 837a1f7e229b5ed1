"""How large each of `representations.py`'s five fields is at a budget of bytes, torch-free, so that a command
can refuse a kind or a budget before it loads anything heavy (`snapshot3d bench fit --representations`)."""
from __future__ import annotations

import math
from dataclasses import dataclass

from snapshot3d import formats
from snapshot3d.errors import UserError

__all__ = ["KINDS", "RepSize", "size_for_budget", "HEAD_HIDDEN", "HASH_LEVELS", "HASH_FEATURES", "HASH_MIN_RES",
           "HASH_MAX_RES", "PE_FREQS", "MLP_HIDDEN_LAYERS"]

KINDS = ("triplane-shared", "triplane", "grid", "hash", "mlp")
HEAD_HIDDEN = 32        # the per-scene head: features -> 32 -> 32 -> (density logit, r, g, b)
HASH_LEVELS, HASH_FEATURES, HASH_MIN_RES, HASH_MAX_RES = 8, 2, 4, 256
PE_FREQS = 6            # the MLP's positional encoding: x, sin and cos of 2^k pi x for k < PE_FREQS
MLP_HIDDEN_LAYERS = 3


@dataclass(frozen=True)
class RepSize:
    """A representation's shape at one budget: `res` (R, G, the hash table's T, or the MLP's width) and
    `channels` (C, or the hash grid's L * F features; the MLP's input width)."""

    kind: str
    res: int
    channels: int
    carried: int   # bytes carried (parameters at one byte each; the shared decoder not counted)


def _head_params(features: int, hidden: int = HEAD_HIDDEN) -> int:
    return features * hidden + hidden + hidden * hidden + hidden + hidden * 4 + 4


def _mlp_params(width: int) -> int:
    d_in = 3 + 6 * PE_FREQS
    return d_in * width + width + (MLP_HIDDEN_LAYERS - 1) * (width * width + width) + width * 4 + 4


def _channels(budget: int) -> int:
    """Feature channels of the planes and the grid: 4 up to 16 kB, 8 up to 64 kB, then 12 (the product's ladder)."""
    return 4 if budget <= 16 * formats.KB else 8 if budget <= 64 * formats.KB else formats.C_MAX


def size_for_budget(kind: str, budget: int) -> RepSize:
    """The largest `kind` whose carried bytes fit `budget` bytes. UserError when none fits."""
    if kind not in KINDS:
        raise UserError(f"unknown representation {kind!r}; choose from {', '.join(KINDS)}")
    c = _channels(budget)
    if kind == "triplane-shared":
        res = int(math.isqrt(budget // (3 * c)))
        size = RepSize(kind, res, c, 3 * c * res * res)
    elif kind == "triplane":
        res = int(math.isqrt(max(0, budget - _head_params(3 * c)) // (3 * c)))
        size = RepSize(kind, res, c, 3 * c * res * res + _head_params(3 * c))
    elif kind == "grid":
        res = int(round((max(0, budget - _head_params(c)) / c) ** (1 / 3)))
        while res > 0 and c * res ** 3 + _head_params(c) > budget:
            res -= 1
        size = RepSize(kind, res, c, c * res ** 3 + _head_params(c))
    elif kind == "hash":
        f = HASH_LEVELS * HASH_FEATURES
        table = max(0, budget - _head_params(f)) // f
        size = RepSize(kind, table, f, table * f + _head_params(f))
    else:
        width = 1
        while _mlp_params(width + 1) <= budget:
            width += 1
        size = RepSize(kind, width, 3 + 6 * PE_FREQS, _mlp_params(width))
    if size.res < 2:
        raise UserError(f"{budget} bytes hold no {kind} field")
    return size
