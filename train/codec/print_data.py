"""Training captures of the print codec, made through the real channel: a host photo and a stand-in scene
are embedded (`snapshot3d.codecs.print_embed`), laid out as a sheet, printed and photographed by `simulate`
and rectified by `scan`, exactly the way a user's print goes. The restore network's front-end learns to
tell the payload from the host and the print from these pairs. Made by worker processes (one per core),
written in chunks that a later run skips (resumable).

A chunk `captures-NNNN.npz` holds `capture` (N, 380, 380, 3) uint8 RGB (what `scan` gives), `snapshot`
(N, 380, 380, 3) uint8 RGB (what was printed: what the front-end must restore) and `info` (JSON: host,
severity, seed, planes, print dots per pixel).

Hosts: the bundled photos and, when `../shared/data` is present, `hosts/train/` (never `hosts/heldout/`,
and never the bundled coffee and chelsea, which the benchmarks hold out).
"""
from __future__ import annotations

import json
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.errors import UserError

__all__ = ["CaptureConfig", "host_sources", "host_name", "read_host", "make_capture", "make_captures", "load_captures", "HELD_OUT_HOSTS", "FRONT_END_CODEC"]

HELD_OUT_HOSTS = ("coffee", "chelsea")
FRONT_END_CODEC = "print-1"
"""the print codec of the front-end's training snapshots (a bench row, not shipped; its weights were trained on it)"""
_PLANES = ((32, 4), (24, 4), (48, 4), (64, 8), (16, 4))
_SEVERITIES = ("mild", "moderate", "severe", "jpeg75")
_SEVERITY_P = (0.3, 0.35, 0.3, 0.05)
_DOTS = (2, 3, 4, 4, 6, 8)   # printer dots per snapshot pixel: prints of about 50 to 200 mm at 600 dpi


@dataclass(frozen=True)
class CaptureConfig:
    """How many training captures to make, and how."""

    count: int = 1200
    chunk: int = 40
    seed: int = 0
    host_psnr_min: float = 31.0
    host_psnr_max: float = 34.0


def host_sources() -> list[str]:
    """Training hosts: 'builtin:NAME' for bundled photos (not the held-out ones) and file paths of
    `../shared/data/hosts/train/*.jpg` when present."""
    from snapshot3d.builtin import shared_data_dir
    from snapshot3d.scanner.backgrounds import background_names

    out = [f"builtin:{n}" for n in background_names() if n not in HELD_OUT_HOSTS]
    root = shared_data_dir()
    if root is not None and (root / "hosts" / "train").is_dir():
        out += sorted(str(p) for p in (root / "hosts" / "train").glob("*.jpg"))
    return out


def host_name(spec: str) -> str:
    """The name of a `host_sources` entry: the bundled photo's name, or the file's stem."""
    return spec.split(":", 1)[1] if spec.startswith("builtin:") else Path(spec).stem


def read_host(spec: str) -> np.ndarray:
    """A `host_sources` entry -> the whole photo, (H, W, 3) uint8 RGB; UserError naming an unreadable file."""
    from snapshot3d.scanner.backgrounds import load_background

    if spec.startswith("builtin:"):
        return np.asarray(load_background(spec.split(":", 1)[1]))
    img = cv2.imread(spec, cv2.IMREAD_COLOR)
    if img is None:
        raise UserError(f"cannot read the training host photo {spec} (not an image, or damaged)")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def _host(spec: str, rng: np.random.Generator) -> np.ndarray:
    """A random square crop of a host photo, resized to the snapshot: (380, 380, 3) float32 RGB in [0, 1]."""
    img = read_host(spec)
    h, w = img.shape[:2]
    side = int(min(h, w) * rng.uniform(0.55, 1.0))
    y0, x0 = rng.integers(0, h - side + 1), rng.integers(0, w - side + 1)
    n = formats.SNAPSHOT_SIZE
    crop = cv2.resize(np.ascontiguousarray(img[y0:y0 + side, x0:x0 + side]), (n, n), interpolation=cv2.INTER_AREA)
    if rng.random() < 0.5:
        crop = crop[:, ::-1]
    return np.ascontiguousarray(crop).astype(np.float32) / 255.0


def make_capture(host_spec: str, seed: int, cfg: CaptureConfig = CaptureConfig()):
    """One training pair: (capture (380, 380, 3) uint8, snapshot (380, 380, 3) uint8, info dict), or None
    when `scan` does not find the sheet in the photo."""
    from snapshot3d.codecs import print_embed, print_source
    from snapshot3d.scanner.qr import SheetMeta
    from snapshot3d.scanner.roundtrip import capture as scan_capture

    rng = np.random.default_rng([cfg.seed, seed])
    res, ch = _PLANES[rng.integers(len(_PLANES))]
    host = _host(host_spec, rng)
    planes = print_source.random_planes(res, ch, rng)
    target_db = float(rng.uniform(cfg.host_psnr_min, cfg.host_psnr_max))
    snap = print_embed.embed(host, planes, target_db, codec=FRONT_END_CODEC)
    severity = str(rng.choice(_SEVERITIES, p=_SEVERITY_P))
    dots = int(rng.choice(_DOTS))
    meta = SheetMeta(codec=FRONT_END_CODEC, box=(-1, -1, -1, 1, 1, 1), orbit=(3.0, 20.0, 40.0), planes=(res, ch))
    try:
        capture = scan_capture(snap, meta, severity, int(rng.integers(2 ** 31)), print_dots=dots)
    except UserError:
        return None
    info = {"host": Path(host_spec).name, "severity": severity, "dots": dots, "planes": [int(res), int(ch)],
            "host_psnr_target": round(target_db, 2), "seed": int(seed)}
    return capture, snap, info


def _chunk_job(args):
    index, sources, cfg = args
    cv2.setNumThreads(1)
    rng = np.random.default_rng([cfg.seed, 10_000 + index])
    caps, pays, infos, k = [], [], [], 0
    while len(caps) < cfg.chunk:
        spec = sources[int(rng.integers(len(sources)))]
        got = make_capture(spec, index * 100_000 + k, cfg)
        k += 1
        if got is not None:
            caps.append(got[0]), pays.append(got[1]), infos.append(got[2])
    return index, np.stack(caps), np.stack(pays), infos


def make_captures(folder: Path, cfg: CaptureConfig = CaptureConfig(), workers: int = 0, log=print) -> list[Path]:
    """Make (or complete) `cfg.count` captures in `folder`, `cfg.chunk` per file; returns the chunk files."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    sources = host_sources()
    chunks = -(-cfg.count // cfg.chunk)
    path = lambda i: folder / f"captures-{i:04d}.npz"  # noqa: E731
    todo = [i for i in range(chunks) if not path(i).is_file()]
    if todo:
        log(f"making {len(todo) * cfg.chunk} captures through simulate + scan ({len(sources)} hosts) in {folder}")
    workers = workers or os.cpu_count() or 1
    with ProcessPoolExecutor(workers) as pool:
        for done, (i, caps, pays, infos) in enumerate(pool.map(_chunk_job, [(i, sources, cfg) for i in todo]), 1):
            tmp = path(i).with_name(path(i).name + ".partial")
            with open(tmp, "wb") as f:
                np.savez(f, capture=caps, snapshot=pays, info=np.frombuffer(json.dumps(infos).encode(), np.uint8))
            tmp.replace(path(i))
            log(f"captures chunk {i} written ({done}/{len(todo)})")
    return [path(i) for i in range(chunks)]


def load_captures(files) -> tuple[np.ndarray, np.ndarray, list]:
    """All chunks: captures and snapshots (N, 380, 380, 3) uint8, infos."""
    caps, pays, infos = [], [], []
    for f in files:
        with np.load(f) as z:
            caps.append(z["capture"]), pays.append(z["snapshot"])
            infos += json.loads(z["info"].tobytes().decode())
    return np.concatenate(caps), np.concatenate(pays), infos
