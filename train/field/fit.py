"""Fitting a scene's planes against posed images with the frozen shared decoder.

`fit()` is the whole job (resumable through a checkpoint); `train_step()` is one optimisation step,
shared with the joint decoder training.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from snapshot3d import formats
from snapshot3d.carve import carve
from snapshot3d.errors import UserError
from snapshot3d.posed import PosedImages
from snapshot3d.scene import dequantize_planes, quantize_planes

from .channel_fit import through_channel
from .config import FitConfig, check_fit_config
from .field import TriPlanes, frozen, straight_through_8bit
from .occupancy import OccupancyGrid
from .rays import RayBank, make_rays, recomposite
from .render import density_fn, render_rays
from .sampler import BoxFrame

if TYPE_CHECKING:
    from .seen_ground import GroundRays

__all__ = ["FitConfig", "FitState", "new_state", "train_step", "fit", "FitResult", "empty_alpha"]


@dataclass
class FitState:
    """Mutable training state of one scene."""

    planes: TriPlanes
    occ: OccupancyGrid
    frame: BoxFrame
    bank: RayBank
    opt: torch.optim.Optimizer
    step: int = 0
    samples: int = 0
    rays: int = 0
    train_seconds: float = 0.0
    channel: tuple | None = None
    """(D, a, s) of `channel_fit.response_tensors` when cfg.channel_fraction > 0"""
    background: torch.nn.Module | None = None
    """`background.OuterField` with cfg.background "outer" (never written to the snapshot), else None"""
    bg_opt: torch.optim.Optimizer | None = None
    poses: torch.nn.Module | None = None
    """`pose_refine.PoseRefine` of the training views with cfg.refine_poses (never written to the snapshot), else None"""
    pose_opt: torch.optim.Optimizer | None = None
    head: torch.nn.Module | None = None
    """`head.HeadDecoder`, the decoder with the scene's own last layer (in `opt`), with cfg.head "on", else None"""
    ground: GroundRays | None = None
    """`seen_ground.GroundRays`: the bank's rays that show the ground, with cfg.seen_ground_weight, else None"""


@dataclass
class FitResult:
    codes: np.ndarray
    state: FitState
    seconds: float
    log: list = field(default_factory=list)
    ending: dict | None = None
    """with `fit(..., ending=)`: which last phase was kept and what the model expected of each"""
    head: str | None = None
    """with cfg.head "on": the scene's own head as carried (the h= text, `snapshot3d.head`)"""


def hull_grid(posed: PosedImages, res: int = formats.OCC_RES) -> torch.Tensor | None:
    if posed.alpha is None:
        return None
    tr = posed.train
    return torch.from_numpy(carve(posed.alpha[tr], posed.c2w[tr], posed.intrinsics[tr], posed.box, res))


def new_state(posed: PosedImages, cfg: FitConfig, init_planes: torch.Tensor | None = None,
              hull: torch.Tensor | None = None, device=None) -> FitState:
    """Planes, occupancy grid and training rays of one scene, on `device` (None: the CPU)."""
    check_fit_config(cfg)
    device = torch.device(device or "cpu")
    frame = BoxFrame.from_box(posed.box, device)
    planes = TriPlanes(cfg.plane_res, cfg.plane_channels, seed=cfg.seed)
    if init_planes is not None:
        planes.planes.data.copy_(init_planes)
    planes.to(device)
    occ = OccupancyGrid(hull=hull if hull is not None else hull_grid(posed)).to(device)
    opt = torch.optim.Adam(planes.parameters(), lr=cfg.lr)
    bg = bg_opt = None
    if cfg.background == "outer":
        from .background import OuterField
        ground = posed.info.get("ground_z") is not None   # the box's floor is the ground (commands._tightened)
        depth = cfg.ground_depth if cfg.ground_depth >= 0 else posed.info.get("ground_depth", 0.0)
        bg = OuterField(cfg.background_res, floor=cfg.ground_texture if ground else 0,
                        floor_depth=depth / frame.scale, floor_reach=cfg.ground_reach).to(device)
        bg_opt = torch.optim.Adam(bg.parameters(), lr=cfg.background_lr)
    poses = pose_opt = None
    if cfg.refine_poses == "on":
        from .pose_refine import PoseRefine
        poses = PoseRefine(len(posed.train)).to(device)
        pose_opt = torch.optim.Adam(poses.parameters(), lr=cfg.pose_lr)
    bank = make_rays(posed, posed.train, frame, cfg.random_background)
    if bank.fg is None and cfg.object_rays and posed.info.get("object_cells") is not None:   # docs/capture.md
        from .object_rays import object_ray_index
        tr = posed.train
        bank.fg = torch.from_numpy(object_ray_index(posed.info["object_cells"], posed.info["object_cells_box"],
                                                    posed.c2w[tr], posed.intrinsics[tr], posed.height, posed.width))
    return FitState(planes, occ, frame, bank.to(device), opt,
                    channel=new_state_channel(cfg, device), background=bg, bg_opt=bg_opt, poses=poses,
                    pose_opt=pose_opt, ground=_ground_rays(posed, cfg, bg is not None, device))


def _ground_rays(posed: PosedImages, cfg: FitConfig, outer: bool, device):
    """`seen_ground.ground_rays` of posed (its spared cells on `device`), where cfg.seen_ground_weight and the
    background model ask for them and the sparse box found them, else None."""
    if not outer or cfg.seen_ground_weight <= 0:
        return None
    from .seen_ground import ground_rays
    return ground_rays(posed.info, posed.height, posed.width, cfg.seen_ground_spare, device)


def new_state_channel(cfg: FitConfig, device=None) -> tuple | None:
    """`FitState.channel` of `cfg`: (D, gain, noise) of the print channel's stand-in, (R, R) each (gain all
    ones unless cfg.channel_gain), or None when cfg.channel_fraction is 0."""
    if cfg.channel_fraction <= 0:
        return None
    from .channel_fit import response_tensors
    channel = response_tensors(cfg.plane_res, cfg.plane_channels, device, gain=cfg.channel_gain)
    if channel is None:
        raise UserError("--channel-fraction needs the print channel's model in budget-curves.json; "
                        "run 'snapshot3d bench print-predict'")
    return channel


def _tv(p: torch.Tensor) -> torch.Tensor:
    return ((p[..., 1:, :] - p[..., :-1, :]) ** 2).mean() + ((p[..., :, 1:] - p[..., :, :-1]) ** 2).mean()


def empty_alpha(density, hull: torch.Tensor, frame: BoxFrame, n: int, gen: torch.Generator) -> torch.Tensor:
    """Mean one-step alpha of `density(points (M, 3)) -> (M,)` at random points outside the visual hull
    (G, G, G) bool: a field must be empty there by itself, since the decode side computes its occupancy from
    the field alone."""
    pts = (torch.rand(n, 3, generator=gen) * 2 - 1).to(frame.centre.device)
    g = hull.shape[0]
    cell = ((pts + 1) * 0.5 * g).long().clamp(0, g - 1)
    sigma = density(pts[~hull[cell[:, 0], cell[:, 1], cell[:, 2]]])
    return torch.mean(1 - torch.exp(-sigma * frame.step))


def lr_at(cfg: FitConfig, step: int) -> float:
    return cfg.lr * (cfg.lr_final / cfg.lr) ** min(1.0, step / max(1, cfg.steps))


def train_step(st: FitState, decoder, cfg: FitConfig, gen: torch.Generator, extra_params_opt=None,
               channels: int | None = None, plane_noise: float = 0.0, plane_fn=None) -> float:
    """One step on a batch of rays; updates planes (and the decoder when `extra_params_opt` is given).
    `channels` < C zeroes the trailing plane channels (nested channels while training the decoder);
    `plane_noise` > 0 adds Gaussian noise of that std to the planes the decoder reads (robustness to
    what a medium restores); `plane_fn` maps the planes the decoder reads (after both) to others."""
    t0 = time.perf_counter()
    for g in st.opt.param_groups:
        g["lr"] = lr_at(cfg, st.step) * g.get("scale", 1.0)
    if st.head is not None:   # the scene's own head in place of the shared decoder's last layer
        decoder = st.head
        st.head.quantize = st.step >= cfg.steps * (1 - cfg.qat_fraction)
    if st.bg_opt is not None:
        for g in st.bg_opt.param_groups:
            g["lr"] = lr_at(cfg, st.step) * cfg.background_lr / cfg.lr
    o, d, target, view, cover = st.bank.batch(cfg.batch_rays, cfg.fg_fraction, gen)
    move_poses = st.poses is not None and st.step >= cfg.steps * cfg.pose_start
    if st.poses is not None:
        for g in st.pose_opt.param_groups:
            g["lr"] = lr_at(cfg, st.step) * cfg.pose_lr / cfg.lr
        o, d = st.poses(view, o, d)
    planes = st.planes.planes
    if st.channel is not None and st.step >= cfg.steps * (1 - cfg.channel_fraction):
        dct, gain, noise = st.channel   # what a print restores
        planes = straight_through_8bit(through_channel(planes, dct, gain, cfg.channel_noise * noise, gen))
    elif st.step >= cfg.steps * (1 - cfg.qat_fraction):
        planes = straight_through_8bit(planes)
    if channels is not None and channels < planes.shape[1]:
        planes = planes[:, :channels]
    if plane_noise > 0:
        planes = planes + plane_noise * torch.randn(planes.shape, generator=gen).to(planes.device)
    if plane_fn is not None:
        planes = plane_fn(planes)
    occ = st.occ.occ if cfg.occupancy else None
    bg_terms = None
    if st.background is not None:
        from .background import render_and_regularise
        color, n_samples, bg_terms = render_and_regularise(planes, decoder, st.frame, occ, st.background, cfg, o, d,
                                                           target, gen)
    else:
        behind = formats.BACKGROUND
        if cfg.random_background and cover is not None:   # a haze where the target is clear shows over a colour
            behind = torch.rand(o.shape[0], 3, generator=gen).to(o.device)
            target = recomposite(target, cover, behind, formats.BACKGROUND)
        color, _, n_samples = render_rays(planes, decoder, st.frame, occ, o, d, jitter=True, generator=gen,
                                          min_transmittance=cfg.min_transmittance, background=behind)
    st.samples += n_samples
    mse = torch.mean((color - target) ** 2)
    loss = mse + cfg.tv_weight * _tv(st.planes.planes) if cfg.tv_weight else mse
    if bg_terms is not None:
        loss = loss + bg_terms
    if st.ground is not None:   # pixels that show the ground: their rays pass the box empty
        loss = loss + cfg.seen_ground_weight * _seen_ground_opacity(st, planes, decoder, occ, cfg.batch_rays // 8, gen)
    if cfg.empty_weight and st.occ.outside_hull:
        loss = loss + cfg.empty_weight * empty_alpha(density_fn(planes, decoder), st.occ.hull, st.frame,
                                                     cfg.batch_rays // 2, gen)
    st.opt.zero_grad(set_to_none=True)
    if extra_params_opt is not None:
        extra_params_opt.zero_grad(set_to_none=True)
    for extra in (st.bg_opt, st.pose_opt):
        if extra is not None:
            extra.zero_grad(set_to_none=True)
    loss.backward()
    st.opt.step()
    if st.bg_opt is not None:
        st.bg_opt.step()
    if move_poses:
        st.pose_opt.step()
        st.poses.hold_gauge()
    if extra_params_opt is not None:
        extra_params_opt.step()
    st.planes.clamp_()
    st.step += 1
    st.rays += o.shape[0]
    if cfg.occupancy and st.step >= cfg.occ_warmup and st.step % cfg.occ_every == 0:
        st.occ.update(density_fn(st.planes.planes.detach(), decoder), st.frame.step, gen)
    st.train_seconds += time.perf_counter() - t0
    return float(mse.detach())


def _seen_ground_opacity(st: FitState, planes: torch.Tensor, decoder, occ, n: int, gen: torch.Generator) -> torch.Tensor:
    """Mean opacity of the planes (`seen_ground.clear_opacity`) along n of st.ground's rays drawn at random, at the
    refined poses."""
    from .seen_ground import clear_opacity
    k = st.ground.index[torch.randint(len(st.ground.index), (n,), generator=gen)].to(st.bank.rgb.device)
    o, d = st.bank.origins[k], st.bank.dirs[k]
    if st.poses is not None:
        o, d = st.poses(st.bank.view[k], o, d)
    return clear_opacity(planes, decoder, st.frame, occ, o, d, st.ground.plane, st.ground.clear, gen,
                         st.ground.spared).mean()


def _save_ckpt(path: Path, st: FitState, cfg: FitConfig, gen: torch.Generator, scene: str):
    tmp = path.with_name(path.name + ".partial")
    torch.save({"cfg": asdict(cfg), "scene": scene, "step": st.step, "planes": st.planes.state_dict(), "occ": st.occ.state_dict(),
                "opt": st.opt.state_dict(), "gen": gen.get_state(), "seconds": st.train_seconds,
                "rays": st.rays, "samples": st.samples,
                **({"background": st.background.state_dict(), "bg_opt": st.bg_opt.state_dict()}
                   if st.background is not None else {}),
                **({"poses": st.poses.state_dict(), "pose_opt": st.pose_opt.state_dict()}
                   if st.poses is not None else {}),
                **({"head": st.head.state_dict()} if st.head is not None else {})},
               tmp)
    tmp.replace(path)


def _load_ckpt(path: Path, st: FitState, cfg: FitConfig, gen: torch.Generator, scene: str) -> bool:
    if not path.is_file():
        return False
    ck = torch.load(path, weights_only=False, map_location=st.frame.centre.device)
    if ck.get("cfg") != asdict(cfg) or ck.get("scene") != scene:
        raise UserError(f"checkpoint {path} was made for another scene or other settings; "
                        "delete it or fit with the same settings")
    st.planes.load_state_dict(ck["planes"]), st.occ.load_state_dict(ck["occ"]), st.opt.load_state_dict(ck["opt"])
    gen.set_state(ck["gen"])
    if st.background is not None:
        st.background.load_state_dict(ck["background"]), st.bg_opt.load_state_dict(ck["bg_opt"])
    if st.poses is not None:
        st.poses.load_state_dict(ck["poses"]), st.pose_opt.load_state_dict(ck["pose_opt"])
    if st.head is not None:
        st.head.load_state_dict(ck["head"])
    st.step, st.train_seconds, st.rays, st.samples = ck["step"], ck["seconds"], ck["rays"], ck["samples"]
    return True


def fit(posed: PosedImages, decoder, cfg: FitConfig, checkpoint: Path | None = None, progress=None,
        init_planes: torch.Tensor | None = None, hull: torch.Tensor | None = None, device=None,
        object_bar=None, ending=None) -> FitResult:
    """Optimise planes for `posed` with the frozen `decoder` on `device` (None: the CPU; the decoder is
    moved there). `progress(step, psnr)` is called every few steps; `object_bar(steps)` gives that callback
    for the object-alone step's fit, when it runs. With `checkpoint`, state is saved every
    `cfg.checkpoint_every` steps and a run resumes from it. `ending` (an `ending.Ending`; not with a
    background model): the last phase is run both plain and through the channel's noise, and the channel
    ending is kept where `ending.score` expects it `ending.MARGIN_DB` better (`FitResult.ending` says which; with
    a head of the scene's own, unless it expects it that much worse)."""
    frozen(decoder)
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    st = new_state(posed, cfg, init_planes, hull, device)
    decoder.to(st.frame.centre.device)
    if cfg.head == "on":
        from .head import own_head
        st.head = own_head(decoder)
        st.opt.add_param_group({"params": st.head.head_parameters(), "lr": cfg.head_lr, "scale": cfg.head_lr / cfg.lr})
    if checkpoint is not None:
        _load_ckpt(checkpoint, st, cfg, gen, posed.name)
    log = []
    fork_at = cfg.steps - int(cfg.steps * cfg.qat_fraction)
    if ending is None or st.background is not None or st.channel is not None or st.step > fork_at:
        fork_at = cfg.steps
    _run(st, decoder, cfg, gen, fork_at, log, progress, checkpoint, posed.name)
    chosen = None
    if st.step < cfg.steps:
        st, chosen = _two_endings(st, decoder, cfg, gen, ending, log, progress, checkpoint, posed.name)
    # the planes of the object alone (object_carve.py), unless the automatic box looked for the ground and did not find
    # it: the ground then stays in the box as one piece with the object, and the step only costs (docs/capture.md)
    lost_ground = "ground_z" in posed.info and posed.info["ground_z"] is None
    if st.background is not None and cfg.object_steps > 0 and not lost_ground:
        from .object_carve import object_config, object_views, subpixel_for
        poses = None if st.poses is None else st.poses.params.detach().cpu().numpy()
        now = decoder if st.head is None else st.head
        target = object_views(st.planes.planes.detach(), now, posed, poses, cfg.object_silhouette,
                              cfg.object_base_keep, cfg.object_halo, cfg.object_opaque,
                              subpixel_for(cfg.object_subpixel, cfg.plane_res))
        if target is not None:
            sub = object_config(cfg)
            alone = fit(target[0], now, sub, init_planes=st.planes.planes.detach(), hull=target[1],
                        device=st.frame.centre.device, progress=object_bar(sub.steps) if object_bar else None)
            st.planes.planes.data.copy_(alone.state.planes.planes.detach())
            if st.head is not None:
                st.head.load_state_dict(alone.state.head.state_dict())
    codes = quantize_planes(st.planes.planes.detach().cpu().numpy())
    head = None
    if st.head is not None:
        from .head import head_text
        head = head_text(st.head)
    return FitResult(codes=codes, state=st, seconds=st.train_seconds, log=log, ending=chosen, head=head)


def _run(st: FitState, decoder, cfg: FitConfig, gen, until: int, log: list | None, progress, checkpoint, name):
    """Train `st` up to step `until`, logging (when `log` is a list), reporting and checkpointing as `fit`."""
    ema = None
    while st.step < until:
        mse = train_step(st, decoder, cfg, gen)
        ema = mse if ema is None else 0.9 * ema + 0.1 * mse
        if log is not None and (st.step % 25 == 0 or st.step == cfg.steps):
            psnr = -10 * math.log10(max(ema, 1e-10))
            log.append({"step": st.step, "train_psnr": round(psnr, 3), "seconds": round(st.train_seconds, 2),
                        "occupied": round(float(st.occ.occ.float().mean()), 4)})
            if progress is not None:
                progress(st.step, psnr)
        if checkpoint is not None and st.step % cfg.checkpoint_every == 0:
            _save_ckpt(checkpoint, st, cfg, gen, name)


def _carried_head(decoder, head):
    """The shared `decoder` with `head`'s last layer as its codes carry it (`head.with_head`)."""
    from .head import head_text, with_head
    return with_head(decoder, head_text(head))


def _two_endings(st: FitState, decoder, cfg: FitConfig, gen, ending, log, progress, checkpoint, name):
    """`fit`'s last phase run plain and through `ending.channel` from the same state -> (the kept state,
    {"kept": "plain" | "channel", "e2e_expected": {ending: dB}, "seconds": the second ending's})."""
    from .ending import MARGIN_DB, fork
    twin, twin_gen = fork(st, gen)
    _run(st, decoder, cfg, gen, cfg.steps, log, progress, checkpoint, name)
    t0 = twin.train_seconds
    twin.channel = ending.channel
    _run(twin, decoder, replace(cfg, channel_fraction=cfg.qat_fraction), twin_gen, cfg.steps, None, None, None, name)
    scores = {k: ending.score(dequantize_planes(quantize_planes(s.planes.planes.detach().cpu().numpy())),
                              decoder if s.head is None else _carried_head(decoder, s.head))
              for k, s in (("plain", st), ("channel", twin))}
    # a scene's own head is fitted to the planes it reads: plain, it makes the views more sensitive to the print's
    # noise than the model sees (spot 16x4 at moderate: the model -0.02 dB, measured +0.60), so with a head the
    # channel ending is kept unless the model expects it MARGIN_DB worse (docs/fitting.md)
    margin = -MARGIN_DB if st.head is not None else MARGIN_DB
    kept = "channel" if scores["channel"] >= scores["plain"] + margin else "plain"
    info = {"kept": kept, "e2e_expected": {k: round(v, 3) for k, v in scores.items()},
            "seconds": round(twin.train_seconds - t0, 1)}
    if kept == "channel":
        twin.channel = None
        twin.train_seconds += st.train_seconds - t0   # both endings' time counts
        return twin, info
    st.train_seconds += twin.train_seconds - t0
    return st, info
