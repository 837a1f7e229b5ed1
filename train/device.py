"""`--device auto|cpu|cuda` for every training command (DESIGN section 2): CPU is the default that CI
and users without a GPU run; a lent GPU trains the same code. Random numbers are drawn on the CPU from
seeded generators and moved, so a run is reproducible on either device."""
from __future__ import annotations

import torch

from snapshot3d.errors import UserError

__all__ = ["resolve_device"]


def resolve_device(name: str = "auto") -> torch.device:
    """'auto' (CUDA when present, else CPU), 'cpu' or 'cuda' -> a torch.device; UserError when CUDA is
    asked for and absent."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if name == "cuda":
        if not torch.cuda.is_available():
            raise UserError("--device cuda: no CUDA device is available here (torch "
                            f"{torch.__version__}); use --device cpu or auto")
        return torch.device("cuda")
    raise UserError(f"--device must be auto, cpu or cuda, not {name!r}")
