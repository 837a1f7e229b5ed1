"""torch -> ONNX: the restore network and the renderer's two field graphs, with parity checks.

Public surface: `export_all(out_dir)` (export.onnx_export), `field_parity`, `restore_parity`
(export.parity), the graphs `RestoreGraph`, `ProjectGraph`, `FieldGraph` (export.models)."""

__all__ = ["export_all", "field_parity", "restore_parity", "RestoreGraph", "ProjectGraph", "FieldGraph"]

_WHERE = {"export_all": "onnx_export", "field_parity": "parity", "restore_parity": "parity",
          "RestoreGraph": "models", "ProjectGraph": "models", "FieldGraph": "models"}


def __getattr__(name):
    from importlib import import_module
    if name in _WHERE:
        return getattr(import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
