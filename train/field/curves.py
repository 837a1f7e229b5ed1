"""The codec benches' curves and the print channel's model that fitting reads (`snapshot3d/assets/
budget-curves.json`, written by `bench capacity` and `bench print-predict`); torch-free, below both the budget
(`budget.py`) and the channel-aware fit (`channel_fit.py`)."""
from __future__ import annotations

__all__ = ["CURVES_FILE", "PREDICT_HOSTS", "codec_curves", "print_channel"]

CURVES_FILE = "budget-curves.json"
PREDICT_HOSTS = ("builtin:coffee", "builtin:chelsea")


def codec_curves() -> tuple[dict, object]:
    import json

    from snapshot3d.paths import asset

    path = asset(CURVES_FILE)
    return (json.loads(path.read_text()) if path.is_file() else {}), path


def print_channel():
    """The print channel's model (`print_channel.ChannelModel`) from budget-curves.json, or None."""
    from snapshot3d.codecs.print_channel import ChannelModel

    ch = codec_curves()[0].get("print", {}).get("channel")
    return ChannelModel(float(ch["gain"]), float(ch["unit"])) if ch else None
