"""Where the package's shipped files live (torch-free): `snapshot3d/assets/` holds the decoder and
codec weights, the ONNX models, the default scene and the demo's example photo."""
from __future__ import annotations

from importlib import resources
from pathlib import Path

from . import formats

__all__ = ["asset", "model_file"]


def asset(name: str = "") -> Path:
    """Path of a shipped file (the assets folder itself for "")."""
    base = Path(str(resources.files("snapshot3d") / "assets"))
    return base / name if name else base


def model_file(kind: str, codec: str | None = None, decoder: str | None = None) -> str:
    """File name of an exported model: kind 'restore' (a file medium's restore network; names its codec,
    default `formats.FILE_CODEC`), 'restore-print' (the print medium's receiver, one graph for every print
    codec), 'project' or 'field' (name their decoder version, default `formats.DECODER_VERSION`)."""
    decoder = decoder or formats.DECODER_VERSION
    return {"restore": f"restore-{codec or formats.FILE_CODEC}.onnx", "restore-print": "restore-print.onnx",
            "project": f"project-{decoder}.onnx", "field": f"field-{decoder}.onnx"}[kind]
