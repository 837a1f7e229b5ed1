"""Fitting the tri-plane field (torch): planes against posed images with occupancy-based empty-space
skipping (`fit`, `sampler`, `occupancy`, `rays`), the reference renderer (`render`), the shared decoder
and its training (`decoder`), held-out measures (`evaluate`), the plane-size ladder (`budget`), the
typed configs (`config`, torch-free) and the `fit`, `render`, `mesh` and `train decoder` commands
(`commands`). Submodules are imported where they are used (nothing at import time)."""

__all__ = ["fit", "field", "sampler", "occupancy", "rays", "render", "decoder", "evaluate", "budget", "config",
           "commands"]
