"""Measurement, not product: every `snapshot3d bench ...` runner, its charts and the calibration
experiments. Each module writes CSV, JSON and PNG under `bench/results/` with the machine's core count.
Product packages (`snapshot3d` core, `scanner`, `viewer`, `train`, `export`) never import this package
(`tests/test_layers.py` proves it); it sits on top and may import any of them."""

__all__ = ["fit", "scan", "channel", "codec", "codec_jpeg", "capacity", "capacity_model", "oracle", "decode", "common"]
