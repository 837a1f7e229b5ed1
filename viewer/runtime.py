"""onnxruntime sessions for the shipped models (numpy and onnxruntime only; never torch).

Session options are tuned for a phone-class CPU: all graph optimisations, one intra-op thread per
core, sequential execution, memory-pattern reuse (the shapes repeat chunk after chunk), and threads that
sleep between runs instead of spinning: a spinning thread takes a core from the numpy and OpenCV work
between runs and from the renderer's threads (on 2 shared cores the bake ran slower with it, issue 39)."""
from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.paths import asset, model_file

__all__ = ["FieldModels", "field_models", "model_path", "session", "model_metadata"]


@dataclass(frozen=True)
class FieldModels:
    """The renderer's two graphs (onnxruntime sessions, or anything with their `run`): `project`
    (planes, interp -> tables) and `field` (tables, rows -> density_logit, rgb); see `export.models`."""

    project: object
    field: object


def model_path(kind: str, codec: str | None = None, decoder: str | None = None) -> Path:
    """kind 'restore' (of `codec`, default the file medium's current one), 'restore-print', 'project' or
    'field' (of `decoder`, default `formats.DECODER_VERSION`) -> the packaged model file."""
    return asset(model_file(kind, codec, decoder))


def field_models(threads: int | None = None, decoder: str = formats.DECODER_VERSION) -> FieldModels:
    """The project and field graphs of decoder version `decoder` (a scene's `decoder_version`)."""
    return FieldModels(session(str(model_path("project", decoder=decoder)), threads),
                       session(str(model_path("field", decoder=decoder)), threads))


@lru_cache(maxsize=16)
def session(path: str, threads: int | None = None):
    import onnxruntime as ort

    if not Path(path).is_file():
        raise UserError(f"model not found: {path}; run 'snapshot3d export'")
    so = ort.SessionOptions()
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.intra_op_num_threads = threads or os.cpu_count() or 1
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.enable_mem_pattern = True
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])


def model_metadata(path: str) -> dict:
    return dict(session(path).get_modelmeta().custom_metadata_map)
