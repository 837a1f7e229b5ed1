"""Weights files of the trained networks (codecs, front-ends): an `.npz` of the state dict as float32 numpy
arrays plus the config they were built from as JSON, written atomically; read back into a frozen module."""
from __future__ import annotations

import json
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np
import torch

from snapshot3d.errors import UserError

__all__ = ["save_weights", "load_weights"]


def save_weights(net: torch.nn.Module, cfg, path: Path) -> None:
    """Atomic write of `net`'s weights (float32) and the dataclass `cfg` they were built from."""
    path = Path(path)
    arrays = {k: v.detach().cpu().float().numpy() for k, v in net.state_dict().items()}
    arrays["__config__"] = np.frombuffer(json.dumps(asdict(cfg)).encode(), np.uint8)
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "wb") as f:
        np.savez(f, **arrays)
    tmp.replace(path)


def load_weights(path: Path, config_type, build, what: str, command: str):
    """(module in eval mode with frozen weights, config) from `path`: `build(cfg)` makes the module; `what`
    and `command` name the file and how to make it in the one-line errors."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{what} weights not found: {path}; run '{command}'")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = dict(z)
        raw = json.loads(arrays.pop("__config__").tobytes().decode())
    except (OSError, ValueError, KeyError) as e:
        raise UserError(f"{path} is not a {what} weights file ({type(e).__name__})") from None
    known = {f.name for f in fields(config_type)}
    cfg = config_type(**{k: v for k, v in raw.items() if k in known})
    net = build(cfg)
    net.load_state_dict({k: torch.from_numpy(v) for k, v in arrays.items()})
    net.eval()
    for p in net.parameters():
        p.requires_grad_(False)
    return net, cfg
