"""The typed config of the file codec's network and its training run (torch-free, so the CLI can build its options from them).

Each field's `help` is its documentation and its `--option` text.
"""
from __future__ import annotations

from dataclasses import dataclass

from snapshot3d.options import config_field as _f

__all__ = ["CodecConfig"]


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
    sharing: bool = _f(False, "train through what sharing a file does (JPEG 60-95 with 4:2:0, once or twice, resizing "
                              "0.6x-2.8x and back; `channel.SharingRanges`) instead of the print-and-capture channel")
    file_copies: bool = _f(False, "train through copies of the file as `embed` writes it (4x): the PNG, JPEG 60-95 of the "
                                   "4x file, or the 4x file resized to 0.6x-3x of 380 px (mostly smaller) and JPEG "
                                   "there, read back as `restore` does (`file_copies.FileCopyRanges`), in place of --sharing's channel")
    copy_resize_prob: float = _f(0.55, "--file-copies: probability that a copy is resized (else the PNG or a JPEG of "
                                       "the 4x file)")
    copy_shrink_share: float = _f(0.75, "--file-copies: share of the resized copies that are smaller than 380 px")
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
