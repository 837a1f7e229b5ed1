"""Typed configs of fitting and of the shared decoder's training (torch-free, so the CLI can build its options from them).

Each field's `help` is its documentation and its `--option` text.
"""
from __future__ import annotations

from dataclasses import dataclass

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.options import config_field

__all__ = ["FitConfig", "DecoderConfig", "LADDER", "LADDER_PRINT", "check_fit_config"]


@dataclass
class FitConfig:
    """Settings of one plane fit (stored in checkpoints)."""

    plane_res: int = config_field(64, "R: plane resolution (R x R per plane)")
    plane_channels: int = config_field(8, "C: channels per plane (at most formats.C_MAX)")
    steps: int = config_field(1500, "optimisation steps")
    batch_rays: int = config_field(4096, "rays per step")
    lr: float = config_field(0.04, "Adam learning rate of the plane values at the first step")
    lr_final: float = config_field(0.004, "learning rate at the last step (exponential decay)")
    occ_every: int = config_field(16, "steps between occupancy-grid updates")
    occ_warmup: int = config_field(128, "steps before the first occupancy update (all hull cells occupied until then)")
    occupancy: bool = config_field(True, "occupancy-based empty-space skipping (off: every sample in the box is evaluated)")
    min_transmittance: float = config_field(1e-3, "early ray termination: samples behind this transmittance are dropped (0: off)")
    qat_fraction: float = config_field(0.15, "last fraction of steps trained through the 8-bit rounding the snapshot carries")
    channel_fraction: float = config_field(0.0, "last fraction of steps trained through a model of the print channel "
                                           "(per-DCT-coefficient gain and noise, train/field/channel_fit.py; 0: off)")
    channel_noise: float = config_field(1.0, "scale of the print channel model's noise in that phase, and in the "
                                        "channel ending of --ending auto (1: as measured at the design severity)")
    channel_gain: bool = config_field(False, "in that phase, also the model's per-coefficient gain (the receiver's "
                                      "shrinkage); off: its noise alone, which measured better (bench fit-channel)")
    ending: str = config_field("auto", "with --budget auto --medium print: auto fits each rung's last phase "
                               "(--qat-fraction) both plain and through the print channel model's noise, and keeps "
                               "the second where the model expects it at least 0.3 dB better at held-out views "
                               "(train/field/ending.py; not with --background outer); plain: the plain ending alone")
    refit: str = config_field("auto", "with --budget auto --medium print: the chosen rung (fine-tuned from the "
                              "largest) is fitted again from scratch; auto keeps that fit where the print channel's "
                              "model expects it no worse, and for the object alone (--background outer with "
                              "--object-steps) also where it leaves less opacity outside the largest rung's outline "
                              "at the held-out views (fewer floaters, docs/capture.md); model: only where the model "
                              "expects it no worse; always: keeps it")
    head: str = config_field("auto", "a head of the scene's own: the shared decoder's last layer refitted for this "
                             "scene and carried in its metadata (136 bytes for tri-dec-1; docs/fitting.md); auto: on "
                             "with --medium print, where the planes are small and the QR code carries it")
    head_lr: float = config_field(3e-3, "with --head on: the head's learning rate (decayed as the planes')")
    fg_fraction: float = config_field(0.75, "share of each batch drawn from rays that see the object (when masks exist)")
    tv_weight: float = config_field(1e-4, "total-variation weight on the planes")
    empty_weight: float = config_field(1.0, "weight of the density penalty at random points outside the visual hull")
    random_background: bool = config_field(False, "train each ray over a random colour, its target recomposited by the "
                                                   "images' coverage, so that a haze where they are clear costs (needs "
                                                   "coverage: masks or RGBA; the object-alone step always does)")
    seed: int = config_field(0, "random seed")
    decoder: str = config_field(formats.DECODER_VERSION, "shared decoder version to fit for: "
                                + ", ".join(formats.DECODERS) + " (docs/fitting.md)")
    checkpoint_every: int = config_field(250, "steps between checkpoints")
    background: str = config_field("auto", "what the rays end on: white (the snapshot's background; captures "
                                   "with masks or on white), or outer: a coarse contracted field outside the box and "
                                   "a colour per direction, fitted with the planes and never carried in the snapshot "
                                   "(captures of a room without masks; the box is then found from the cameras' "
                                   "overlap and the density, train/field/background.py); auto: outer for a "
                                   "capture without masks whose frames' borders are not white, else white (a "
                                   "fit's core treats auto as white)")
    background_res: int = config_field(48, "with --background outer: cells per axis of the outer field's grid")
    background_samples: int = config_field(24, "with --background outer: outer-field samples per ray before the "
                                           "box and as many after it")
    background_lr: float = config_field(0.05, "with --background outer: the outer field's learning rate (decayed as "
                                        "the planes')")
    ground_texture: int = config_field(128, "with --background outer and the ground found under the object (the "
                                       "box's floor cut there): texels per side of a colour texture on the ground "
                                       "under that floor, the ground's look where it meets the object (part of the "
                                       "background model, never carried; 0: off; docs/capture.md)")
    ground_reach: float = config_field(1.0, "with --ground-texture: the texture spans this many times the box's "
                                       "floor about its centre, and rays that leave the box through its sides end on "
                                       "it too (the ground just round the object, else the coarse outer field's; "
                                       "at 2 on three 120 deg arcs: -0.3 to -0.4 dB, so 1; docs/capture.md)")
    ground_depth: float = config_field(-1.0, "with --ground-texture: how far below the box's floor the texture's "
                                       "plane lies (world units); -1: where the ground is, the floor's lift over the "
                                       "ground that the sparse points found (0 where a pre-fit's density found it, "
                                       "the floor cut at the top of the ground's cell)")
    distortion_weight: float = config_field(0.0, "with --background outer: weight of mip-NeRF 360's distortion loss "
                                            "on the box samples' weights (floaters spread along a ray cost)")
    opacity_weight: float = config_field(0.0, "with --background outer: weight of each ray's opacity in the box "
                                         "where the background model alone already gives its pixel")
    opacity_entropy: bool = config_field(False, "with --background outer: that weight on the binary entropy of every "
                                         "ray's opacity instead (a ray ends on the object or passes to the background)")
    wall_weight: float = config_field(0.0, "with --background outer: weight of a density penalty at random points "
                                      "near the box's side walls and top (not its floor)")
    floor_weight: float = config_field(0.0, "with --background outer: weight of a density penalty in the box's floor "
                                       "band where nothing stands above it (the ground left over the ground cut)")
    seen_ground_weight: float = config_field(-1.0, "with --background outer and the ground found from the photos' "
                                             "sparse points: weight of the planes' opacity along the rays of the "
                                             "pixels where a matched feature lies on the ground, which cross the box "
                                             "empty (train/field/seen_ground.py); -1: auto, 0.3 where the training "
                                             "cameras span less than 300 deg round the object (a frontal arc: "
                                             "fewer floaters), else 0 (docs/capture.md; a fit's core treats -1 as 0)")
    ground_sweep: bool = config_field(False, "with --seen-ground-weight: also count as showing the ground the "
                                      "pixels whose window agrees with the views about 20 deg away warped through the "
                                      "ground plane and not through planes a little over it (snapshot3d/ground_sweep.py; "
                                      "7-9% of a frontal arc's pixels, against about 1% from the matched "
                                      "features; off: on the 120 deg arcs the bunny lost 1.8 dB, the rest "
                                      "moved within the fits' spread, docs/capture.md)")
    seen_ground_spare: bool = config_field(False, "with --seen-ground-weight: the penalty skips the samples in the "
                                           "object's cells as the object-box fit found them (--object-box), so "
                                           "that rays passing close by the object do not wear its edge away (on "
                                           "the 120 deg arcs: +0.3 dB, the floaters over 2% on 2 of 7; off by "
                                           "default, docs/capture.md)")
    object_rays: bool = config_field(False, "with --background outer, --object-box and no masks: draw "
                                     "--fg-fraction of each batch from the rays that cross the object-box fit's "
                                     "cells, as a fit given masks draws them from the masks (spot's 120 deg arc, "
                                     "one fit: -1.5 dB and 2.8% outside against 1.0%; off, docs/capture.md)")
    wall_margin: float = config_field(0.15, "with --background outer: depth of the walls' and the floor's bands, a "
                                      "fraction of the box's half-size (at most 0.25)")
    refine_poses: str = config_field("auto", "learn a small correction of each training view's pose with the "
                                     "planes (a rotation about the camera and a shift, train/field/pose_refine.py): "
                                     "on, off, or auto: on for nerfstudio and COLMAP captures (poses from a solver "
                                     "or an app), from half the steps at the earliest where --bundle adjusted them "
                                     "to the photos' matches first; off for builtin and Blender scenes (exact "
                                     "poses; a fit's core treats auto as off)")
    pose_lr: float = config_field(1e-3, "with --refine-poses: the corrections' learning rate (decayed as the planes')")
    pose_start: float = config_field(0.1, "with --refine-poses: fraction of the steps before the corrections move (the "
                                     "planes first take a rough shape)")
    tighten_sides: bool = config_field(True, "with --background outer and --box auto: the short pre-fit also cuts "
                                       "the box's sides and top to where its density lies, with a margin "
                                       "(train/field/box_tighten.py; fewer floaters, bench capture-background)")
    sparse_box: bool = config_field(True, "with --background outer and --box auto: find the ground and the object "
                                    "from the training photos' sparse 3D points (SIFT matched and triangulated at the "
                                    "capture's poses, snapshot3d/sparse_box.py) before the short pre-fit, which then "
                                    "runs only when they show no ground with an object on it")
    bundle: str = config_field("auto", "with --sparse-box: adjust the training poses to the photos' matched features "
                               "first (a small bundle adjustment, snapshot3d/bundle.py): fit: the box is cut from "
                               "the points at the adjusted poses and the fit starts from them; box: the box only; "
                               "off; auto: fit for nerfstudio and COLMAP captures, or with --refine-poses on, else off")
    object_steps: float = config_field(0.5, "with --background outer: after the fit, this share of its steps more "
                                       "takes the planes to the object alone, against their own views with the "
                                       "ground, the shadow and the haze cut away (train/field/object_carve.py; "
                                       "skipped when the automatic box found no ground); 0: off")
    object_box: float = config_field(0.5, "with --background outer, --box auto and the ground found: a fit of this "
                                     "share of the steps in the tightened box finds the object's cells "
                                     "(object_carve.object_cells), and the planes are fitted in the box round them "
                                     "(train/field/box_tighten.py: more texels on the object); 0: off")
    object_silhouette: float = config_field(0.2, "with --object-steps: the object's cells that fall outside the "
                                            "object's silhouette in more than this share of the training photos "
                                            "that see them are cut too (each photo cut by GrabCut from the planes' "
                                            "own view, train/field/silhouette.py: the ground-coloured skirt under "
                                            "the object); 1: off")
    object_base_keep: float = config_field(0.05, "with --object-silhouette under 1: the floor band's solid cells that "
                                           "its rule drops (nothing standing over them: a broad base on the "
                                           "ground) are kept when they fall outside the photos' silhouettes in "
                                           "fewer than this share of the views that see them; 0: off")
    object_halo: float = config_field(1.0, "with --object-silhouette under 1: the cells that growing the object's "
                                      "cells adds (a halo the fit paints round its outline) are cut where they fall "
                                      "outside the photos' silhouettes, not grown, in more than this share of the "
                                      "views that see them, at every height (measured: it cuts the object's skin "
                                      "too, docs/capture.md); 1: off")
    object_opaque: float = config_field(0.02, "with --object-steps: the opacity of the views the object alone is "
                                        "fitted to, made solid (a real object is opaque): from 0 to 1 over this "
                                        "width about one half (the views' outline, as a mask; docs/capture.md); 1: "
                                        "as rendered")
    object_subpixel: int = config_field(0, "with --object-opaque under 1: the views' opacity is made solid on a grid "
                                        "this many times finer than their pixels and averaged back, so that the "
                                        "outline is anti-aliased as a camera's is; 1: on the pixels (a step); 0: "
                                        "auto, 4 where the planes are at most 32 texels a side (a print's small "
                                        "rungs), else 1 (docs/capture.md)")
    object_channel: float = config_field(-1.0, "with --object-steps: the last fraction of the object fit's steps "
                                         "trained through the print channel model's noise (as --channel-fraction); "
                                         "0: as --channel-fraction says; -1: auto, --qat-fraction with --medium "
                                         "print, else 0 (docs/capture.md)")


@dataclass
class DecoderConfig:
    """Joint training of the shared decoder over built-in scenes (spot and lego are held out)."""

    scenes: tuple = config_field(("procedural", "duck", "teapot", "bunny", "suzanne"), "builtin scenes trained on")
    version: str = config_field(formats.DECODERS[-1], "decoder version the weights are written as")
    hidden: int = config_field(64, "decoder width (tri-dec-1: 32)")
    layers: int = config_field(2, "hidden layers (ReLU) before the head")
    steps: int = config_field(15000, "total steps, the scenes (and their plane sizes) taken in turn")
    plane_res: tuple = config_field((16, 32, 64), "R of each training scene's planes (tri-dec-1: 64 alone): one plane "
                                    "set per scene and R, so that one decoder serves small payloads too")
    nested: tuple = config_field((4, 8, 12), "channel counts drawn each step, so that one decoder serves any C")
    plane_noise: float = config_field(0.0, "each step adds Gaussian noise to the planes the decoder reads, its std "
                                      "drawn uniformly in [0, this] (plane values span [-1, 1]); 0: off")
    channel_noise: float = config_field(0.0, "at the print ladder's plane sizes (LADDER_PRINT), the planes the decoder "
                                        "reads get the print channel model's noise per DCT coefficient "
                                        "(channel_fit.py), scaled by a factor drawn uniformly in [0, this]; 0: off")
    lr: float = config_field(3e-3, "decoder Adam learning rate, decayed 10x over the run")
    init: str = config_field("", "start the decoder from these weights (a shipped version such as tri-dec-2, or a "
                                 "file from 'train decoder -o'; --hidden and --layers must match it); empty: random")
    size: int = config_field(200, "rendered view size of the training scenes")
    seed: int = config_field(0, "random seed")


def _ranges(cfg: FitConfig) -> list[tuple[str, bool, str]]:
    """(option, holds, what it must be) for every numeric bound of a fit's settings (NaN holds none)."""
    def v(option: str):
        return getattr(cfg, option.replace("-", "_"))
    return [
        ("plane-channels", 1 <= cfg.plane_channels <= formats.C_MAX, f"in 1..{formats.C_MAX}"),
        ("plane-res", cfg.plane_res >= 2, ">= 2"),
        *((k, v(k) >= 1, ">= 1") for k in ("steps", "batch-rays", "occ-every", "checkpoint-every")),
        *((k, v(k) > 0, "> 0") for k in ("lr", "lr-final", "pose-lr", "background-lr", "head-lr")),
        *((k, 0 <= v(k) <= 1, "in [0, 1]") for k in ("qat-fraction", "channel-fraction", "fg-fraction")),
        *((k, 0 <= v(k) < 1, "in [0, 1)") for k in ("min-transmittance", "pose-start")),
        *((k, v(k) >= 0, ">= 0") for k in ("channel-noise", "distortion-weight", "opacity-weight",
                                           "wall-weight", "floor-weight")),
        ("background-res", cfg.background_res >= 4, ">= 4"),
        ("background-samples", cfg.background_samples >= 2, ">= 2"),
        ("ground-texture", 0 <= cfg.ground_texture <= 1024, "in 0..1024"),
        ("ground-depth", cfg.ground_depth >= 0 or cfg.ground_depth == -1, ">= 0, or -1 (where the ground is)"),
        ("ground-reach", 1 <= cfg.ground_reach <= 16, "in [1, 16]"),
        ("seen-ground-weight", cfg.seen_ground_weight >= 0 or cfg.seen_ground_weight == -1, ">= 0, or -1 (auto)"),
        ("object-channel", 0 <= cfg.object_channel <= 1 or cfg.object_channel == -1, "in [0, 1], or -1 (auto)"),
        ("object-steps", 0 <= cfg.object_steps <= 4, "in [0, 4]"),
        ("object-box", 0 <= cfg.object_box <= 1, "in [0, 1]"),
        ("object-silhouette", 0 <= cfg.object_silhouette <= 1, "in [0, 1]"),
        ("object-base-keep", 0 <= cfg.object_base_keep <= 1, "in [0, 1]"),
        ("object-halo", 0 <= cfg.object_halo <= 1, "in [0, 1]"),
        ("object-opaque", 0 < cfg.object_opaque <= 1, "in (0, 1]"),
        ("object-subpixel", 0 <= cfg.object_subpixel <= 16, "in 0..16 (0: auto)"),
        ("wall-margin", 0 < cfg.wall_margin <= 0.25, "in (0, 0.25]"),
    ]


def check_fit_config(cfg: FitConfig) -> FitConfig:
    """Refuse settings no fit can run with (one-line `UserError` naming each option that is out of range and
    its value); returns `cfg`."""
    problems = [f"--{k} must be {what}, not {getattr(cfg, k.replace('-', '_'))!r}"
                for k, ok, what in _ranges(cfg) if not ok]
    for option, value, allowed in (("ending", cfg.ending, ("auto", "plain")),
                                   ("refit", cfg.refit, ("auto", "model", "always")),
                                   ("background", cfg.background, ("auto", "white", "outer")),
                                   ("refine-poses", cfg.refine_poses, ("auto", "on", "off")),
                                   ("bundle", cfg.bundle, ("auto", "fit", "box", "off")),
                                   ("head", cfg.head, ("auto", "on", "off"))):
        if value not in allowed:
            problems.append(f"--{option} must be {', '.join(allowed[:-1])} or {allowed[-1]}, not {value!r}")
    if cfg.decoder not in formats.DECODERS:
        problems.append(f"--decoder must be one of {', '.join(formats.DECODERS)}, not {cfg.decoder!r}")
    if problems:
        raise UserError("; ".join(problems))
    return cfg


# `fit --budget auto`: (plane_res, plane_channels) from large to small; all within the paper's 160 kB.
LADDER = ((64, 12), (64, 8), (48, 8), (48, 4), (32, 4))
# `fit --budget auto --medium print`: a photographed print carries about a hundred times less than a file
# (bench capacity), so its ladder goes further down
LADDER_PRINT = ((64, 8), (48, 4), (32, 4), (24, 4), (16, 4))
