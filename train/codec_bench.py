"""The rows of `snapshot3d bench codec` (run by `codec_bench_run`): host fidelity against restore
fidelity, through the real channel.

Every snapshot goes the user's way: sheet -> `simulate` (severity, seed) -> `scan` -> restore -> the 20
orbit views, compared with the views of the original planes (`restore_psnr`). Rows (codec.csv):
- `ours` and `digital` (the same network and budget trained without the channel, baseline a) at
  every severity, for each evaluation scene, host and seed; `ours-refined`: ours with the snapshot
  refined at embed time (`snapshot3d embed`'s default, `train.codec_refine`);
- `ours` at several embedding strengths (the host-vs-restore trade-off);
- `lsb` (baseline b): 8-bit plane codes in the two least-significant bits of the host;
- `views-N` (baseline c): N fixed rendered orbit views carried instead of planes (the Video Snapshot /
  IICNet idea), scored on the views they carry and on the orbit views they cannot produce;
- `arch`: restore time of the reverse pass at 380x380 for several depths and widths.
"""
from __future__ import annotations

import time

import cv2
import numpy as np
import torch

from snapshot3d import codec_layout, formats
from snapshot3d.errors import UserError
from snapshot3d.metrics import psnr as _psnr, ssim
from snapshot3d.scene import dequantize_planes, quantize_planes

from .codec import build_codec, embed_planes, restore_secret
from .codec_commands import scene_meta
from .codec_refine import snapshot_of
from .commands import orbit_cameras
from .config import CodecConfig
from .decoder import load_decoder
from .render import render_views

__all__ = ["capture_seeds", "through_channel", "lsb_embed", "lsb_extract", "FIELDS", "ViewJudge"]


def psnr(a, b) -> float:
    """PSNR capped at 100 dB (an exact copy), so that reports stay valid JSON."""
    return float(min(_psnr(a, b), 100.0))


FIELDS = ["method", "scene", "host", "severity", "seed", "strength", "host_psnr", "host_ssim", "restore_psnr",
          "detected", "views", "carried_psnr", "uncarried_psnr", "blocks", "width", "params", "restore_ms"]


def capture_seeds(severity: str, seeds: int):
    """Seeds to capture a severity with: `seeds` photos for the physical ones, one for the digital ones
    (a JPEG file or a lossless copy does not depend on the seed)."""
    return range(seeds) if severity in ("mild", "moderate", "severe") else [0]


def through_channel(snap: np.ndarray, meta, severity: str, seed: int) -> np.ndarray | None:
    """snapshot (380, 380, 3) uint8 RGB -> the rectified snapshot `scan` gives from a simulated photo of
    its sheet, or None when the sheet is not found."""
    from snapshot3d.scanner.scan import scan_image
    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.scanner.simulate import simulate

    data, _, _ = simulate(render_sheet(snap, meta, 4), severity, seed)
    try:
        return scan_image(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)).snapshot
    except UserError:
        return None


def lsb_embed(host8: np.ndarray, codes: np.ndarray, bits: int = 2) -> np.ndarray:
    """Plane codes (uint8, any shape) into the `bits` least-significant bits of host8 (uint8 RGB)."""
    stream = np.unpackbits(codes.ravel()).reshape(-1, bits)
    vals = (stream * (1 << np.arange(bits - 1, -1, -1))).sum(1).astype(np.uint8)
    flat = host8.ravel().copy()
    if len(vals) > flat.size:
        raise ValueError("planes do not fit the host's low bits")
    flat[:len(vals)] = (flat[:len(vals)] & (0xFF ^ ((1 << bits) - 1))) | vals
    return flat.reshape(host8.shape)


def lsb_extract(img8: np.ndarray, shape: tuple, bits: int = 2) -> np.ndarray:
    n = int(np.prod(shape)) * 8 // bits
    vals = img8.ravel()[:n] & ((1 << bits) - 1)
    stream = ((vals[:, None] >> np.arange(bits - 1, -1, -1)) & 1).astype(np.uint8)
    return np.packbits(stream.ravel()).reshape(shape)


class ViewJudge:
    """Renders the orbit views of planes and scores them against the original scene's."""

    def __init__(self, scene, size: int):
        self.scene, self.size, self.decoder = scene, size, load_decoder()
        self.cams = orbit_cameras(scene, formats.ORBIT_VIEWS, size)
        self.ref = self.views(scene.planes())

    def views(self, planes: np.ndarray) -> np.ndarray:
        return render_views(torch.from_numpy(planes), self.decoder, self.scene.box, *self.cams, self.size, self.size)

    def restore_psnr(self, secret: np.ndarray) -> float:
        planes = codec_layout.secret_to_planes(secret, self.scene.resolution, self.scene.channels)
        return psnr(self.views(dequantize_planes(quantize_planes(planes))), self.ref)


def _codec_rows(method, net, judge, scene_name, host_name, host, severities, seeds, strength, refine=0):
    """Rows of one embedding (`refine` > 0: the snapshot refined that many steps, as `embed --refine`)."""
    scene = judge.scene
    snap = snapshot_of(net, host, scene.planes(), refine, strength)
    host8 = (host * 255 + 0.5).astype(np.uint8)
    base = {"method": method, "scene": scene_name, "host": host_name, "strength": strength,
            "host_psnr": psnr(snap / 255, host8 / 255), "host_ssim": ssim(snap / 255, host8 / 255)}
    rows = []
    for sev in severities:
        for seed in capture_seeds(sev, seeds):
            rect = through_channel(snap, scene_meta(scene, strength), sev, seed)
            row = dict(base, severity=sev, seed=seed, detected=int(rect is not None))
            if rect is not None:
                row["restore_psnr"] = judge.restore_psnr(restore_secret(net, rect, strength))
            rows.append(row)
    return rows, snap


def _lsb_rows(judge, scene_name, host_name, host, severities):
    host8 = (host * 255 + 0.5).astype(np.uint8)
    codes = judge.scene.codes
    snap = lsb_embed(host8, codes)
    base = {"method": "lsb", "scene": scene_name, "host": host_name, "host_psnr": psnr(snap / 255, host8 / 255),
            "host_ssim": ssim(snap / 255, host8 / 255)}
    rows = []
    for sev in severities:
        rect = through_channel(snap, scene_meta(judge.scene, 1.0), sev, 0)
        row = dict(base, severity=sev, seed=0, detected=int(rect is not None))
        if rect is not None:
            planes = dequantize_planes(lsb_extract(rect, codes.shape))
            row["restore_psnr"] = psnr(judge.views(planes), judge.ref)
        rows.append(row)
    return rows


def _views_rows(net, judge, scene_name, host_name, host, severities, counts=(3, 5, 8)):
    """Baseline c: N orbit views (64x64, one secret channel slot per colour channel) instead of planes."""
    rows = []
    side = formats.CODEC_MAX_RES
    small = np.stack([cv2.resize(v, (side, side), interpolation=cv2.INTER_AREA) for v in judge.ref])
    for n in counts:
        idx = np.round(np.linspace(0, formats.ORBIT_VIEWS, n, endpoint=False)).astype(int)
        pseudo = np.zeros((3, formats.CODEC_CHANNELS, side, side), np.float32)
        pseudo.reshape(-1, side, side)[:3 * n] = small[idx].transpose(0, 3, 1, 2).reshape(-1, side, side) * 2 - 1
        snap = embed_planes(net, host, pseudo)
        host8 = (host * 255 + 0.5).astype(np.uint8)
        for sev in severities:
            rect = through_channel(snap, scene_meta(judge.scene, 1.0), sev, 0)
            row = {"method": f"views-{n}", "scene": scene_name, "host": host_name, "severity": sev, "seed": 0,
                   "views": n, "host_psnr": psnr(snap / 255, host8 / 255), "detected": int(rect is not None)}
            if rect is not None:
                got = codec_layout.secret_to_planes(restore_secret(net, rect), side, formats.CODEC_CHANNELS)
                carried = (got.reshape(-1, side, side)[:3 * n].reshape(n, 3, side, side).transpose(0, 2, 3, 1) + 1) / 2
                row["carried_psnr"] = psnr(np.clip(carried, 0, 1), small[idx])
                # every other orbit view can only be shown as the nearest carried one
                nearest = [int(np.argmin(np.abs(((idx - i + 10) % 20) - 10))) for i in range(formats.ORBIT_VIEWS)]
                others = [i for i in range(formats.ORBIT_VIEWS) if i not in set(idx.tolist())]
                row["uncarried_psnr"] = psnr(np.clip(carried[[nearest[i] for i in others]], 0, 1), small[others])
            rows.append(row)
    return rows


def _arch_rows(grid=((2, 16), (4, 24), (4, 32), (6, 32), (8, 48))):
    rows = []
    x = torch.rand(1, 3, formats.SNAPSHOT_SIZE, formats.SNAPSHOT_SIZE)
    for blocks, width in grid:
        net = build_codec(CodecConfig(blocks=blocks, width=width)).eval()
        times = []
        with torch.no_grad():
            for _ in range(5):
                t0 = time.perf_counter()
                net.reverse(x)
                times.append((time.perf_counter() - t0) * 1e3)
        rows.append({"method": "arch", "blocks": blocks, "width": width, "restore_ms": float(np.median(times)),
                     "params": sum(p.numel() for p in net.parameters())})
    return rows
