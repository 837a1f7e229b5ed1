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

import numpy as np

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.head import head_weights, shared_head
from snapshot3d.paths import asset, model_file

__all__ = ["FieldModels", "field_models", "scene_models", "model_path", "session", "model_metadata", "own_head"]


@dataclass(frozen=True)
class FieldModels:
    """The renderer's two graphs (onnxruntime sessions, or anything with their `run`): `project`
    (planes, interp -> tables) and `field` (tables, rows -> density_logit, rgb, hidden); see `export.models`.
    `head`: (4, H + 1) float32, the scene's own last layer (`snapshot3d.head`) applied to `hidden`, or None
    (the graph's own outputs, the shared decoder's)."""

    project: object
    field: object
    head: np.ndarray | None = None


def model_path(kind: str, codec: str | None = None, decoder: str | None = None) -> Path:
    """kind 'restore' (of `codec`, default the file medium's current one), 'restore-print', 'project' or
    'field' (of `decoder`, default `formats.DECODER_VERSION`) -> the packaged model file."""
    return asset(model_file(kind, codec, decoder))


def field_models(threads: int | None = None, decoder: str = formats.DECODER_VERSION,
                 head: str | None = None) -> FieldModels:
    """The project and field graphs of decoder version `decoder` (a scene's `decoder_version`), with the scene's
    own head when `head` (its h= text) is given."""
    return FieldModels(session(str(model_path("project", decoder=decoder)), threads),
                       session(str(model_path("field", decoder=decoder)), threads),
                       None if head is None else own_head(decoder, head))


def scene_models(scene, threads: int | None = None) -> FieldModels:
    """`field_models` of a scene (`snapshot3d.scene.Scene`): its decoder version's graphs and its own head."""
    return field_models(threads, scene.decoder_version, scene.head)


def own_head(decoder: str, text: str) -> np.ndarray:
    """A scene's head text (the h= field) for decoder version `decoder` -> its last layer (4, H + 1) float32.
    UserError (one line) when the text does not fit that decoder."""
    try:
        return head_weights(_shared_head(decoder), text)
    except ValueError as e:
        raise UserError(f"the scene's head does not fit decoder {decoder}: {e}") from None


@lru_cache(maxsize=4)
def _shared_head(decoder: str) -> np.ndarray:
    """The shipped decoder `decoder`'s last layer [W | b] (4, H + 1) float32 (read once)."""
    path = asset(f"decoder-{decoder}.npz")
    if not path.is_file():
        raise UserError(f"decoder {decoder} is not installed ({path})")
    with np.load(path) as z:
        out = shared_head(dict(z))
    out.flags.writeable = False
    return out


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
