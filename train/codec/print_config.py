"""The typed config of the print codec's restore front-end and its training run (torch-free, so the CLI
can build its options from it). Each field's `help` is its documentation and its `--option` text."""
from __future__ import annotations

from dataclasses import dataclass

from snapshot3d.options import config_field as _f

__all__ = ["PrintCodecConfig"]


@dataclass
class PrintCodecConfig:
    """The print codec's restore front-end and its training run (stored with the weights)."""

    width: int = _f(48, "channels at 1/4 resolution (twice that at 1/8)")
    depth: int = _f(4, "3x3 convolutions at each resolution")
    steps: int = _f(4000, "optimisation steps")
    batch: int = _f(12, "crops per step")
    crop: int = _f(128, "crop side in pixels (a multiple of 8)")
    lr: float = _f(1e-3, "Adam learning rate at the first step (cosine decay to lr/20)")
    captures: int = _f(1600, "training captures to make through simulate + scan (kept in --data, resumable)")
    seed: int = _f(0, "random seed")
    checkpoint_every: int = _f(100, "steps between checkpoints")
