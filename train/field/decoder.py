"""The shared decoder: trained once, jointly with planes for the built-in training scenes, then frozen.

Weights live in the package as `assets/decoder-<DECODER_VERSION>.npz` (numpy arrays, so the torch-free
runtime reads them too), beside a JSON summary of the run that made them.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.paths import asset

from .config import LADDER_PRINT, DecoderConfig, FitConfig
from .field import Decoder, frozen
from .fit import new_state, train_step

__all__ = ["DecoderConfig", "train_decoder", "load_decoder", "read_decoder", "frozen", "decoder_path", "scene_decoder"]


def decoder_path(version: str = formats.DECODER_VERSION) -> Path:
    return asset(f"decoder-{version}.npz")


def load_decoder(version: str = formats.DECODER_VERSION) -> Decoder:
    path = decoder_path(version)
    if not path.is_file():
        raise UserError(f"decoder {version} is not installed ({path}); run 'snapshot3d train decoder'")
    return frozen(read_decoder(str(path)))


def scene_decoder(scene) -> Decoder:
    """The decoder a scene (`snapshot3d.scene.Scene`) renders with: its shared version's, with the scene's own head
    when it has one (`head.with_head`)."""
    from .head import with_head
    return with_head(load_decoder(scene.decoder_version), scene.head)


def read_decoder(spec: str, what: str = "decoder weights") -> Decoder:
    """A trainable Decoder from `spec`: a shipped version's name (`tri-dec-1`) or a weights file from
    'train decoder -o'; `what` names the option in the one-line errors."""
    path = decoder_path(spec) if spec in formats.DECODERS else Path(spec)
    if not path.is_file():
        raise UserError(f"{what} {spec}: not found (give a file from 'train decoder -o' or one of "
                        f"{', '.join(formats.DECODERS)})")
    try:
        with np.load(path) as z:
            return Decoder.from_arrays(dict(z))
    except (OSError, ValueError, KeyError, RuntimeError) as e:
        raise UserError(f"{what} {spec}: not decoder weights ({type(e).__name__})") from None


def _init_decoder(cfg: DecoderConfig) -> Decoder:
    """A trainable copy of the decoder named by `cfg.init`, whose width and depth must be the config's."""
    dec = read_decoder(cfg.init, "--init")
    if (dec.hidden, dec.layers) != (cfg.hidden, cfg.layers):
        raise UserError(f"--init {cfg.init} has width {dec.hidden} and {dec.layers} hidden layers: give --hidden "
                        f"{dec.hidden} --layers {dec.layers}")
    return dec


def _channel_noise_fn(cfg: DecoderConfig, res: int, channels: int, responses: dict, gen: torch.Generator, device):
    """None, or planes (3, channels, res, res) -> the same plus one draw of the print channel model's noise per
    DCT coefficient (`channel_fit.through_channel` without its shrinkage), scaled by U(0, cfg.channel_noise);
    only at the print ladder's plane sizes, where a snapshot can travel as a print."""
    from .channel_fit import response_tensors, through_channel

    if cfg.channel_noise <= 0 or (res, channels) not in LADDER_PRINT:
        return None
    if (res, channels) not in responses:
        got = response_tensors(res, channels, device, gain=False)
        if got is None:
            raise UserError("--channel-noise needs the print channel's model in budget-curves.json")
        responses[(res, channels)] = got
    d, ones, s = responses[(res, channels)]
    scale = cfg.channel_noise * float(torch.rand(1, generator=gen))
    return lambda planes: through_channel(planes, d, ones, scale * s, gen)


def train_decoder(cfg: DecoderConfig, out: Path, checkpoint: Path | None = None, log=print, device=None) -> dict:
    from snapshot3d.loaders import load_scene

    if not (cfg.channel_noise >= 0 and cfg.plane_noise >= 0):   # NaN too
        raise UserError("--channel-noise and --plane-noise must be >= 0")
    init = _init_decoder(cfg) if cfg.init else None   # checked before anything is written, and before the seed
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    runs = [(n, r) for n in cfg.scenes for r in cfg.plane_res]   # one plane set per scene and resolution
    names = [n if len(cfg.plane_res) == 1 else f"{n}@{r}" for n, r in runs]
    per_scene = math.ceil(cfg.steps / len(runs))
    fcfgs = [FitConfig(plane_res=r, plane_channels=formats.C_MAX, steps=per_scene, seed=cfg.seed) for _, r in runs]
    posed = {n: load_scene(f"builtin:{n}", size=cfg.size) for n in cfg.scenes}
    states = [new_state(posed[n], fc, device=device) for (n, _), fc in zip(runs, fcfgs)]
    dec = (init if init is not None else Decoder(hidden=cfg.hidden, layers=cfg.layers)).to(device or "cpu")
    opt = torch.optim.Adam(dec.parameters(), lr=cfg.lr)
    step0, t_start, hist, responses = 0, time.perf_counter(), {n: [] for n in names}, {}
    if checkpoint is not None and checkpoint.is_file():
        ck = torch.load(checkpoint, weights_only=False, map_location=device or "cpu")
        if ck["cfg"] != asdict(cfg):
            raise UserError(f"checkpoint {checkpoint} was made with other settings")
        dec.load_state_dict(ck["dec"]), opt.load_state_dict(ck["opt"]), gen.set_state(ck["gen"])
        for st, s in zip(states, ck["states"]):
            st.planes.load_state_dict(s["planes"]), st.occ.load_state_dict(s["occ"]), st.opt.load_state_dict(s["opt"])
            st.step = s["step"]
        step0, hist = ck["step"], ck["hist"]
    for step in range(step0, per_scene * len(runs)):
        k = step % len(runs)
        for g in opt.param_groups:
            g["lr"] = cfg.lr * 0.1 ** (step / (per_scene * len(runs)))
        c = int(cfg.nested[int(torch.randint(len(cfg.nested), (1,), generator=gen))])
        noise = cfg.plane_noise * float(torch.rand(1, generator=gen)) if cfg.plane_noise > 0 else 0.0
        fn = _channel_noise_fn(cfg, runs[k][1], c, responses, gen, device)
        mse = train_step(states[k], dec, fcfgs[k], gen, extra_params_opt=opt, channels=c, plane_noise=noise,
                         plane_fn=fn)
        hist[names[k]].append(mse)
        if (step + 1) % 250 == 0:
            line = " ".join(f"{n}={-10 * math.log10(np.mean(h[-20:])):.2f}" for n, h in hist.items() if h)
            log(f"step {step + 1}: train psnr {line} ({time.perf_counter() - t_start:.0f}s)")
            if checkpoint is not None:
                tmp = checkpoint.with_name(checkpoint.name + ".partial")
                torch.save({"cfg": asdict(cfg), "step": step + 1, "dec": dec.state_dict(), "opt": opt.state_dict(),
                            "gen": gen.get_state(), "hist": hist,
                            "states": [{"planes": s.planes.state_dict(), "occ": s.occ.state_dict(),
                                        "opt": s.opt.state_dict(), "step": s.step} for s in states]}, tmp)
                tmp.replace(checkpoint)
    np.savez(out, **dec.state_arrays())
    summary = {"decoder_version": cfg.version, "config": asdict(cfg),
               "final_train_psnr": {n: round(-10 * math.log10(np.mean(h[-50:])), 2) for n, h in hist.items()},
               "seconds": round(time.perf_counter() - t_start, 1), "torch_threads": torch.get_num_threads()}
    out.with_suffix(".json").write_text(json.dumps(summary, indent=2))
    return summary
