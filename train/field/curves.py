"""The codec benches' curves and the print channel's model that fitting reads (`snapshot3d/assets/
budget-curves.json`, written by `bench capacity` and `bench print-predict`); torch-free, below both the budget
(`budget.py`) and the channel-aware fit (`channel_fit.py`)."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from snapshot3d.scene import Scene

__all__ = ["CURVES_FILE", "PREDICT_HOSTS", "codec_curves", "codec_psnr", "payload_hint", "print_channel"]

CURVES_FILE = "budget-curves.json"
PREDICT_HOSTS = ("builtin:coffee", "builtin:chelsea")


def codec_curves() -> tuple[dict, object]:
    import json

    from snapshot3d.paths import asset

    path = asset(CURVES_FILE)
    return (json.loads(path.read_text()) if path.is_file() else {}), path


def codec_psnr(medium: str, values: int) -> float:
    """The restore_psnr the medium's codec gives a payload of `values` plane values, interpolated in
    log(values) on the codec bench's curve (clamped to its ends)."""
    from snapshot3d.errors import UserError

    curves, path = codec_curves()
    if medium not in curves:
        raise UserError(f"no codec curve for medium {medium!r} in {path}; run 'snapshot3d bench codec --medium {medium}'")
    pts = sorted(curves[medium]["points"])
    return float(np.interp(np.log(values), np.log([p[0] for p in pts]), [p[1] for p in pts]))


def payload_hint(medium: str, scene: Scene, margin_db: float = 3.0) -> str | None:
    """One line for a print snapshot of planes too large for a photo to carry: the print codec's curve
    (`snapshot3d/assets/budget-curves.json`, `moderate` photos) puts their restore more than `margin_db` below
    its best payload, more than a larger field can win back (plain `fit` writes 64x8: 21.9 dB against 27.9 at
    16x4). None otherwise, and for the file medium, whose curve is flat within 1.5 dB."""
    points = codec_curves()[0].get(medium, {}).get("points", [])
    if medium != "print" or not points:
        return None
    here = codec_psnr(medium, int(scene.codes.size))
    best_values, best_db = max(points, key=lambda p: p[1])
    if here >= best_db - margin_db:
        return None
    return (f"hint: {scene.resolution}x{scene.channels} planes are more than a print carries well (about {here:.1f} "
            f"dB restored from a moderate photo, against {best_db:.1f} at {best_values} plane values); fit with "
            f"'--budget auto --medium print' for the plane size with the best views after printing")


def print_channel():
    """The print channel's model (`print_channel.ChannelModel`) from budget-curves.json, or None."""
    from snapshot3d.codecs.print_channel import ChannelModel

    ch = codec_curves()[0].get("print", {}).get("channel")
    return ChannelModel(float(ch["gain"]), float(ch["unit"])) if ch else None
