"""Training the codec: crops of host photos carry crops of spread planes through the channel; every
`full_every` steps a whole 380x380 snapshot of a real scene adds the plane loss and the view loss
(rays rendered from restored planes through the frozen decoder). The host-loss weight is a Lagrange
multiplier steered so that host PSNR sits at a target that rises to `host_target_db` with the channel's
curriculum (first learn to carry the secret, then to hide it). Resumable from a checkpoint.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from snapshot3d import formats
from snapshot3d.codecs import file_layout
from snapshot3d.errors import UserError
from snapshot3d.train.field.commands import orbit_cameras
from snapshot3d.train.field.decoder import load_decoder
from snapshot3d.train.field.rays import view_rays
from snapshot3d.train.field.render import occupancy_from_planes, render_rays
from snapshot3d.train.field.sampler import BoxFrame

from .channel import ChannelRanges, SharingRanges, apply_channel, apply_sharing, curriculum_level, round_8bit
from .config import CodecConfig
from .data import CodecData, crop_batch, full_sample
from .file_copies import FileCopyRanges, apply_file_copies
from .hinet import build_codec, load_codec, save_codec
from .net import haar

__all__ = ["train_codec", "host_loss", "secret_to_planes_t", "initial_host_logw"]

LOGW_RANGE = (-4.0, 8.0)  # bounds of the log host-loss weight


def host_loss(snap: torch.Tensor, host: torch.Tensor, low_weight: float) -> torch.Tensor:
    """MSE over pixels plus `low_weight` times the MSE of the LL wavelet band (both (B, 3, H, W))."""
    return F.mse_loss(snap, host) + low_weight * F.mse_loss(haar(snap)[:, :3], haar(host)[:, :3]) / 4


def secret_to_planes_t(secret: torch.Tensor, res: int, channels: int) -> torch.Tensor:
    """torch twin of `file_layout.secret_to_planes` for one (24, G, G) secret -> (3, C, R, R)."""
    p = torch.from_numpy(file_layout.unspread_matrix(res, secret.shape[-1]).astype(np.float32)).to(secret.device)
    s = secret.reshape(3, formats.CODEC_CHANNELS, secret.shape[-2], secret.shape[-1])[:, :channels]
    return p @ s @ p.T


class _Views:
    """Rays of each scene's orbit at 64x64 and the occupancy of its original planes (cached)."""

    def __init__(self, decoder):
        self.decoder, self.cache = decoder, {}

    def loss(self, scene, planes_rest: torch.Tensor, gen: torch.Generator, n: int = 1024) -> torch.Tensor:
        if id(scene) not in self.cache:
            planes = torch.from_numpy(scene.planes()).to(planes_rest.device)
            frame = BoxFrame.from_box(scene.box, planes_rest.device)
            c2w, intr = orbit_cameras(scene, formats.ORBIT_VIEWS, 64)
            rays = [view_rays(c2w[i], intr[i], 64, 64, frame) for i in range(len(c2w))]
            o, d = torch.cat([r[0] for r in rays]), torch.cat([r[1] for r in rays])
            occ = occupancy_from_planes(planes, self.decoder, frame)
            with torch.no_grad():
                ref = torch.cat([render_rays(planes, self.decoder, frame, occ, oc, dc)[0]
                                 for oc, dc in zip(o.split(8192), d.split(8192))])
            self.cache[id(scene)] = (frame, occ, o, d, ref)
        frame, occ, o, d, ref = self.cache[id(scene)]
        idx = torch.randint(len(o), (n,), generator=gen).to(o.device)
        col = render_rays(planes_rest, self.decoder, frame, occ, o[idx], d[idx])[0]
        return F.mse_loss(col, ref[idx])


def _psnr(mse: float, peak: float = 1.0) -> float:
    return 10 * math.log10(peak ** 2 / max(mse, 1e-12))


def _channel(snap, level, cfg: CodecConfig, ranges, gen):
    if not cfg.channel:
        return round_8bit(snap)
    if cfg.file_copies:
        return apply_file_copies(snap, level, ranges, gen)
    return (apply_sharing if cfg.sharing else apply_channel)(snap, level, ranges, gen)


def _save_ckpt(path: Path, net, opt, step, logw, gen, rng, cfg, history):
    tmp = path.with_name(path.name + ".partial")
    torch.save({"net": net.state_dict(), "opt": opt.state_dict(), "step": step, "logw": logw,
                "gen": gen.get_state(), "rng": rng.bit_generator.state, "config": asdict(cfg),
                "history": history}, tmp)
    tmp.replace(path)


def initial_host_logw(init: str) -> float:
    """log of the host-loss weight a run starts with: the weight `init`'s own run ended with (the last
    `host_weight` in its summary, `<init>.json`), so that a fine-tune keeps its host instead of first
    trading it away; 0 (weight 1) from scratch or when that summary is missing."""
    summary = Path(init).with_suffix(".json") if init else None
    if summary is None or not summary.is_file():
        return 0.0
    try:
        weight = float(json.loads(summary.read_text())["history"][-1]["host_weight"])
    except (ValueError, KeyError, IndexError, TypeError):
        return 0.0
    return float(np.clip(math.log(max(weight, 1e-6)), *LOGW_RANGE))


def train_codec(cfg: CodecConfig, data: CodecData, out: Path, checkpoint: Path | None = None,
                ranges: ChannelRanges = ChannelRanges(), log=print, device=None) -> dict:
    """Train (or resume) on `device` (None: the CPU) and write the weights to `out`; returns the run's summary.
    The channel is `ranges` (print and capture), `SharingRanges()` with `cfg.sharing`, or `FileCopyRanges()`
    with `cfg.file_copies`; `cfg.jpeg_prob` replaces its JPEG probability."""
    torch.manual_seed(cfg.seed)
    dev = torch.device(device or "cpu")
    net = build_codec(cfg)
    if not 0.0 <= cfg.jpeg_prob <= 1.0:
        raise UserError(f"--jpeg-prob must be in [0, 1], got {cfg.jpeg_prob}")
    for name in ("copy_resize_prob", "copy_shrink_share"):
        if not 0.0 <= getattr(cfg, name) <= 1.0:
            raise UserError(f"--{name.replace('_', '-')} must be in [0, 1], got {getattr(cfg, name)}")
    ranges = replace(FileCopyRanges(resize_prob=cfg.copy_resize_prob, shrink_share=cfg.copy_shrink_share)
                     if cfg.file_copies else SharingRanges() if cfg.sharing else ranges, jpeg_prob=cfg.jpeg_prob)
    if cfg.init:
        start, start_cfg = load_codec(Path(cfg.init))
        arch = ("levels", "blocks", "width", "layers", "clamp")
        if any(getattr(start_cfg, k) != getattr(cfg, k) for k in arch):
            raise UserError(f"--init {cfg.init} has another architecture ({', '.join(arch)} must match)")
        net.load_state_dict(start.state_dict())
        net.requires_grad_(True)
    net.to(dev)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    gen = torch.Generator().manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    versions = sorted({sc.decoder_version for sc in data.scenes})
    if len(versions) > 1:
        raise UserError(f"the training scenes were fitted for different decoders ({', '.join(versions)}); fit them "
                        f"again with one")
    decoder = load_decoder(versions[0] if versions else formats.DECODER_VERSION).to(dev)
    views = _Views(decoder)
    step, logw, history = 0, initial_host_logw(cfg.init), []
    if cfg.init:
        log(f"fine-tune of {cfg.init}: host-loss weight starts at {math.exp(logw):.2f}")
    if checkpoint is not None and checkpoint.is_file():
        ck = torch.load(checkpoint, weights_only=False, map_location=dev)
        if ck["config"] != asdict(cfg):
            raise UserError(f"checkpoint {checkpoint} was made with other settings; delete it or pass the same options")
        net.load_state_dict(ck["net"]), opt.load_state_dict(ck["opt"])
        step, logw, history = ck["step"], ck["logw"], ck["history"]
        gen.set_state(ck["gen"]), setattr(rng.bit_generator, "state", ck["rng"])
        log(f"resumed at step {step}")
    t0, window = time.time(), []
    while step < cfg.steps:
        lr = cfg.lr * 0.1 ** (step / cfg.steps)
        for g in opt.param_groups:
            g["lr"] = lr
        top = curriculum_level(step, cfg.steps, cfg.ramp)
        host, secret = (t.to(dev) for t in crop_batch(data, cfg.batch, cfg.crop, rng, cfg.levels))
        level = (torch.rand(cfg.batch, generator=gen) * top).to(dev)
        snap, z = net(host, secret)
        _, rest = net.reverse(_channel(snap, level, cfg, ranges, gen))
        l_host = host_loss(snap, host, cfg.low_weight)
        l_sec = F.mse_loss(rest, secret)
        l_z = F.mse_loss(z, net.z.expand_as(z))
        loss = math.exp(logw) * l_host + l_sec + cfg.z_weight * l_z
        rec = {"step": step, "level": top, "host_psnr": _psnr(F.mse_loss(snap.clamp(0, 1), host).item()),
               "secret_mse": l_sec.item(), "z_mse": l_z.item()}
        if cfg.full_every and step % cfg.full_every == 0:
            fhost, scene = full_sample(data, rng)
            fhost, planes = fhost.to(dev), torch.from_numpy(scene.planes()).to(dev)
            grid = formats.SNAPSHOT_SIZE >> cfg.levels
            fsnap, _ = net(fhost, torch.from_numpy(file_layout.planes_to_secret(scene.planes(), grid))[None].to(dev))
            _, frest = net.reverse(_channel(fsnap, (torch.rand(1, generator=gen) * top).to(dev), cfg, ranges, gen))
            prest = secret_to_planes_t(frest[0], scene.resolution, scene.channels)
            l_plane = F.mse_loss(prest, planes)
            l_view = views.loss(scene, prest, gen)
            loss = loss + cfg.plane_weight * l_plane + cfg.view_weight * l_view
            rec.update(plane_mse=l_plane.item(), view_psnr=_psnr(l_view.item()),
                       full_host_psnr=_psnr(F.mse_loss(fsnap.clamp(0, 1), fhost).item()))
            if cfg.full_host:
                loss = loss + math.exp(logw) * host_loss(fsnap, fhost, cfg.low_weight)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        target = cfg.host_target_db - cfg.host_target_ramp_db * (1 - curriculum_level(step, cfg.steps, cfg.ramp))
        logw = float(np.clip(logw + 0.005 * np.clip(target - rec["host_psnr"], -10, 10), *LOGW_RANGE))
        step += 1
        window.append(rec)
        if step % 25 == 0 or step == cfg.steps:
            keys = sorted(set().union(*window) - {"step"})
            agg = {k: float(np.mean([r[k] for r in window if k in r])) for k in keys}
            agg.update(step=step, host_weight=math.exp(logw), seconds=round(time.time() - t0, 1))
            history.append(agg)
            log(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in agg.items()}))
            window = []
        if checkpoint is not None and (step % cfg.checkpoint_every == 0 or step == cfg.steps):
            _save_ckpt(checkpoint, net, opt, step, logw, gen, rng, cfg, history)
    save_codec(net, cfg, out)
    return {"config": asdict(cfg), "channel": ranges.as_dict(), "steps": step, "history": history[-8:],
            "train_scenes": [s.name for s in data.scenes], "train_hosts": data.host_names}
