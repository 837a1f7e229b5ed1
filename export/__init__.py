"""torch -> ONNX: the restore network and the renderer's shading graph, with parity checks.

Public surface: `export_all(out_dir)` (export.onnx_export), `shade_parity`, `restore_parity`
(export.parity), the graphs `RestoreGraph`, `ShadeGraph` (export.models)."""

__all__ = ["export_all", "shade_parity", "restore_parity", "RestoreGraph", "ShadeGraph"]

_WHERE = {"export_all": "onnx_export", "shade_parity": "parity", "restore_parity": "parity",
          "RestoreGraph": "models", "ShadeGraph": "models"}


def __getattr__(name):
    from importlib import import_module
    if name in _WHERE:
        return getattr(import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
