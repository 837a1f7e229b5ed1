"""Typed configs of the training jobs (torch-free, so the CLI can build its options from them).

Each field's `help` is its documentation and its `--option` text.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from snapshot3d import formats
from snapshot3d.errors import UserError

__all__ = ["FitConfig", "DecoderConfig", "CodecConfig", "LADDER", "check_fit_config"]


def _f(default, help: str):
    return field(default=default, metadata={"help": help})


@dataclass
class FitConfig:
    """Settings of one plane fit (stored in checkpoints)."""

    plane_res: int = _f(64, "R: plane resolution (R x R per plane)")
    plane_channels: int = _f(8, "C: channels per plane (at most formats.C_MAX)")
    steps: int = _f(1500, "optimisation steps")
    batch_rays: int = _f(4096, "rays per step")
    lr: float = _f(0.04, "Adam learning rate of the plane values at the first step")
    lr_final: float = _f(0.004, "learning rate at the last step (exponential decay)")
    occ_every: int = _f(16, "steps between occupancy-grid updates")
    occ_warmup: int = _f(128, "steps before the first occupancy update (all hull cells occupied until then)")
    occupancy: bool = _f(True, "occupancy-based empty-space skipping (off: every sample in the box is evaluated)")
    min_transmittance: float = _f(1e-3, "early ray termination: samples behind this transmittance are dropped (0: off)")
    qat_fraction: float = _f(0.15, "last fraction of steps trained through the 8-bit rounding the snapshot carries")
    fg_fraction: float = _f(0.75, "share of each batch drawn from rays that see the object (when masks exist)")
    tv_weight: float = _f(1e-4, "total-variation weight on the planes")
    empty_weight: float = _f(1.0, "weight of the density penalty at random points outside the visual hull")
    seed: int = _f(0, "random seed")
    checkpoint_every: int = _f(250, "steps between checkpoints")


@dataclass
class DecoderConfig:
    """Joint training of the shared decoder over built-in scenes (spot and lego are held out)."""

    scenes: tuple = _f(("procedural", "duck", "teapot", "bunny", "suzanne"), "builtin scenes trained on")
    hidden: int = _f(32, "decoder width")
    steps: int = _f(6000, "total steps, the scenes taken in turn")
    plane_res: int = _f(64, "R of each training scene's planes")
    nested: tuple = _f((4, 8, 12), "channel counts drawn each step, so that one decoder serves any C")
    lr: float = _f(3e-3, "decoder Adam learning rate, decayed 10x over the run")
    size: int = _f(200, "rendered view size of the training scenes")
    seed: int = _f(0, "random seed")


@dataclass
class CodecConfig:
    """The hiding network and its training run (stored with the weights and in checkpoints)."""

    levels: int = _f(2, "Haar splits of the host: the secret sits on a grid 2^levels times smaller")
    blocks: int = _f(4, "coupling blocks (depth)")
    width: int = _f(32, "hidden channels of each dense subnet")
    layers: int = _f(3, "convolutions per dense subnet")
    clamp: float = _f(1.0, "bound of the coupling's log-scale")
    steps: int = _f(4000, "optimisation steps")
    batch: int = _f(8, "crops per step")
    crop: int = _f(96, "host crop side of a training step (the network is fully convolutional)")
    lr: float = _f(1e-3, "Adam learning rate at the first step (exponential decay to lr/10)")
    host_target_db: float = _f(38.0, "host PSNR the host-loss weight is steered to (a Lagrange multiplier)")
    host_target_ramp_db: float = _f(10.0, "the target starts this much lower and rises with the curriculum")
    low_weight: float = _f(1.0, "extra weight of the host's low-frequency (LL) band")
    full_every: int = _f(4, "every this many steps, one full 380x380 snapshot with the plane and view losses")
    view_weight: float = _f(1.0, "weight of the view loss (rays rendered through the frozen decoder)")
    plane_weight: float = _f(1.0, "weight of the plane loss (unspread secret vs planes)")
    channel: bool = _f(True, "train through the print-and-capture channel (off: the paper's digital setting, 8-bit only)")
    ramp: float = _f(0.5, "fraction of the run over which the channel level rises from 0 to its maximum")
    jpeg_prob: float = _f(0.6, "probability that a training image goes through JPEG (after the other distortions)")
    init: str = _f("", "codec weights to start from (a fine-tune with the same architecture); empty: random")
    full_host: bool = _f(False, "also put the host loss on every whole snapshot (real scenes' secrets are denser than "
                                "the augmented crops'; without it a run can let whole snapshots drift from the host)")
    z_weight: float = _f(0.0, "weight of the loss pulling the forward pass's lost part z to the learned constant the "
                              "reverse pass uses in its place (0: off, as HiNet)")
    holdout_scenes: str = _f("spot", "comma-separated scenes never trained on (evaluation)")
    holdout_hosts: str = _f("coffee,chelsea", "comma-separated host photos never trained on (evaluation)")
    seed: int = _f(0, "random seed")
    checkpoint_every: int = _f(100, "steps between checkpoints")


def check_fit_config(cfg: FitConfig) -> FitConfig:
    """Refuse settings no fit can run with (one-line `UserError`); returns `cfg`."""
    problems = []
    if not 1 <= cfg.plane_channels <= formats.C_MAX:
        problems.append(f"--plane-channels must be in 1..{formats.C_MAX}")
    if cfg.plane_res < 2:
        problems.append("--plane-res must be >= 2")
    if cfg.steps < 1 or cfg.batch_rays < 1 or cfg.occ_every < 1 or cfg.checkpoint_every < 1:
        problems.append("--steps, --batch-rays, --occ-every and --checkpoint-every must be >= 1")
    if not (cfg.lr > 0 and cfg.lr_final > 0):
        problems.append("--lr and --lr-final must be > 0")
    if not (0 <= cfg.qat_fraction <= 1 and 0 <= cfg.fg_fraction <= 1 and 0 <= cfg.min_transmittance < 1):
        problems.append("--qat-fraction and --fg-fraction must be in [0, 1], --min-transmittance in [0, 1)")
    if problems:
        raise UserError("; ".join(problems))
    return cfg


# `fit --budget auto`: (plane_res, plane_channels) from large to small; all within the paper's 160 kB.
LADDER = ((64, 12), (64, 8), (48, 8), (48, 4), (32, 4))
