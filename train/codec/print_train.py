"""Training the print codec's restore front-end (`print_net.FrontEnd`) on captures made through the real
channel (`print_data`): crops of 128 x 128 on the snapshot's 8-pixel grid, flipped at random; the target is
the snapshot that was printed, the loss its error in the carriers' bands, weighted as the despreader
listens (`print_net.pool_loss`); the held-out loss is compared with the capture's own (the linear reader). The encoder
is fixed (designed, `snapshot3d.codecs.print_read`), so no gradient has to pass through the print: the real
simulator and scanner make every training input. Resumable from a checkpoint; `--device` trains on a GPU
when one is lent. The last 5% of the captures are held out and scored every few hundred steps.

Weights: `bench/models/print-front.npz` (the state dict as numpy arrays and the config as JSON) beside the
run's summary (command, steps, the held-out losses). The product does not ship it: read through the
despreader, the learned front-end lost 0.2-0.5 dB to the raw capture, so `decode` reads the capture
itself and the bench keeps the front-end as its `print-front` row."""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from snapshot3d import formats
from snapshot3d.codecs import print_carriers
from snapshot3d.errors import UserError

from ..weights import load_weights, save_weights
from .print_config import PrintCodecConfig
from .print_data import FRONT_END_CODEC
from .print_net import FrontEnd, pool_loss

__all__ = ["PrintCodecConfig", "train_print_codec", "save_front_end", "load_front_end", "front_end_path",
           "band_weights"]


def front_end_path() -> Path:
    return Path("bench/models/print-front.npz")


def save_front_end(net: FrontEnd, cfg: PrintCodecConfig, path: Path) -> None:
    save_weights(net, cfg, path)


def load_front_end(path: Path | None = None) -> tuple[FrontEnd, PrintCodecConfig]:
    """The front-end in eval mode (default: the bench's weights, `front_end_path`)."""
    return load_weights(Path(path) if path else front_end_path(), PrintCodecConfig,
                        lambda cfg: FrontEnd(cfg.width, cfg.depth), "print codec", "snapshot3d train print-codec")


def band_weights(capture: np.ndarray) -> dict[str, np.ndarray]:
    """How much the despreader listens to each place of each carrier band of a capture (380, 380, 3)
    uint8 (float32 maps, band -> (h, w)): the square of its matched filter's weight, the band's energy
    weight over the cube of the print's noise power there (`print_read.despread`, weighted)."""
    noise = print_carriers.band_noise(capture / 255.0)
    scale = print_carriers.PRINT_NOISE
    return {b: (w / (noise[b] / scale) ** 3).astype(np.float32) for b, w in print_carriers.PRINT_BANDS.items()}


def _batch(caps, snaps, weights, idx, crop: int, rng: np.random.Generator):
    """Crops on the 8-pixel grid (inside the 376-pixel square that level 3 covers), flipped at random."""
    top = (formats.SNAPSHOT_SIZE // 8 * 8 - crop) // 8
    xs, ys, ws = [], [], {b: [] for b in print_carriers.PRINT_BANDS}
    for i in idx:
        y0, x0 = 8 * rng.integers(0, top + 1, 2)
        fy, fx = rng.random(2) < 0.5
        sl = lambda a: a[y0:y0 + crop, x0:x0 + crop]  # noqa: E731
        c, p = sl(caps[i]), sl(snaps[i])
        for b, m in weights[i].items():
            s = 2 ** int(b[-3])
            ws[b].append(m[y0 // s:(y0 + crop) // s, x0 // s:(x0 + crop) // s])
        if fy:
            c, p = c[::-1], p[::-1]
            for b in ws:
                ws[b][-1] = ws[b][-1][::-1]
        if fx:
            c, p = c[:, ::-1], p[:, ::-1]
            for b in ws:
                ws[b][-1] = ws[b][-1][:, ::-1]
        xs.append(c.transpose(2, 0, 1)), ys.append(p.transpose(2, 0, 1))
    x = torch.from_numpy(np.stack(xs).astype(np.float32) / 255.0)
    y = torch.from_numpy(np.stack(ys).astype(np.float32) / 255.0)
    return x, y, {b: torch.from_numpy(np.ascontiguousarray(np.stack(v))) for b, v in ws.items()}


def _held_out_loss(net, caps, snaps, weights, idx, dev) -> float:
    """The loss on whole held-out captures (the error the despreader would see)."""
    losses = []
    with torch.no_grad():
        for i in idx:
            x = torch.from_numpy(caps[i].transpose(2, 0, 1)[None].astype(np.float32) / 255.0).to(dev)
            y = torch.from_numpy(snaps[i].transpose(2, 0, 1)[None].astype(np.float32) / 255.0).to(dev)
            e = formats.SNAPSHOT_SIZE // 8 * 8
            w = {b: torch.from_numpy(m[None, :e // 2 ** int(b[-3]), :e // 2 ** int(b[-3])]).to(dev)
                 for b, m in weights[i].items()}
            losses.append(pool_loss(net(x)[..., :e, :e], y[..., :e, :e], w).item())
    return float(np.mean(losses))


def _baseline_loss(caps, snaps, weights, idx) -> float:
    """The same loss for the capture as it is (the linear reader): what the front-end must beat."""
    e = formats.SNAPSHOT_SIZE // 8 * 8
    losses = []
    for i in idx:
        x, y = (torch.from_numpy(a[i].transpose(2, 0, 1)[None].astype(np.float32) / 255.0)[..., :e, :e]
                for a in (caps, snaps))
        w = {b: torch.from_numpy(m[None, :e // 2 ** int(b[-3]), :e // 2 ** int(b[-3])]) for b, m in weights[i].items()}
        losses.append(pool_loss(x, y, w).item())
    return float(np.mean(losses))


def _settings(cfg: dict) -> dict:
    """What a resumed run must share with its checkpoint (more --steps may extend a run)."""
    return {k: v for k, v in cfg.items() if k not in ("steps", "checkpoint_every")}


def train_print_codec(cfg: PrintCodecConfig, caps: np.ndarray, snaps: np.ndarray, out: Path,
                      checkpoint: Path | None = None, log=print, device=None) -> dict:
    """Train (or resume) on `device` (None: the CPU) and write the weights to `out`; returns the summary."""
    if cfg.crop % 8 or cfg.crop > formats.SNAPSHOT_SIZE // 8 * 8:
        raise UserError(f"--crop must be a multiple of 8 and at most {formats.SNAPSHOT_SIZE // 8 * 8}")
    dev = torch.device(device or "cpu")
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    n = len(caps)
    held = np.arange(n - max(2, n // 20), n)
    train_idx = np.arange(held[0])
    weights = [band_weights(c) for c in caps]
    net = FrontEnd(cfg.width, cfg.depth).to(dev)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    step, history = 0, []
    if checkpoint is not None and checkpoint.is_file():
        ck = torch.load(checkpoint, weights_only=False, map_location=dev)
        if _settings(ck["config"]) != _settings(asdict(cfg)):
            raise UserError(f"checkpoint {checkpoint} was made with other settings; delete it or pass the same options")
        net.load_state_dict(ck["net"]), opt.load_state_dict(ck["opt"])
        step, history = ck["step"], ck["history"]
        rng.bit_generator.state = ck["rng"]
        log(f"resumed at step {step}")
    zero = _baseline_loss(caps, snaps, weights, held[:16])
    log(json.dumps({"held_out_loss_of_capture": zero, "train_captures": int(len(train_idx)), "held_out": int(len(held))}))
    t0, window = time.time(), []
    while step < cfg.steps:
        lr = cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * step / cfg.steps)))
        for g in opt.param_groups:
            g["lr"] = lr
        x, y, w = _batch(caps, snaps, weights, rng.choice(train_idx, cfg.batch), cfg.crop, rng)
        loss = pool_loss(net(x.to(dev)), y.to(dev), {b: v.to(dev) for b, v in w.items()})
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        window.append(loss.item())
        step += 1
        if step % 50 == 0 or step == cfg.steps:
            rec = {"step": step, "loss": float(np.mean(window)), "lr": lr, "seconds": round(time.time() - t0, 1)}
            if step % 500 == 0 or step == cfg.steps:
                rec["held_out_loss"] = _held_out_loss(net, caps, snaps, weights, held[:16], dev)
                rec["held_out_gain_db"] = 10 * math.log10(zero / rec["held_out_loss"])
            history.append(rec)
            log(json.dumps({k: round(v, 6) if isinstance(v, float) else v for k, v in rec.items()}))
            window = []
        if checkpoint is not None and (step % cfg.checkpoint_every == 0 or step == cfg.steps):
            tmp = checkpoint.with_name(checkpoint.name + ".partial")
            torch.save({"net": net.state_dict(), "opt": opt.state_dict(), "step": step, "history": history,
                        "rng": rng.bit_generator.state, "config": asdict(cfg)}, tmp)
            tmp.replace(checkpoint)
    save_front_end(net, cfg, out)
    last = [h for h in history if "held_out_loss" in h]
    return {"config": asdict(cfg), "steps": step, "held_out_loss_of_capture": zero,
            "held_out": last[-1] if last else None, "history": history[-6:], "codec": FRONT_END_CODEC,
            "bands": print_carriers.PRINT_BANDS, "params": int(sum(p.numel() for p in net.parameters()))}
