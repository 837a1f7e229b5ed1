"""torch -> ONNX: the restore graphs (the file codecs' networks, the print medium's designed receiver) and the
renderer's two field graphs, with parity checks.

Public surface: `export_all(out_dir)` (export.onnx_export), `field_parity`, `restore_parity`, `print_parity`
(export.parity), the graphs `RestoreGraph`, `ProjectGraph`, `FieldGraph` (export.models) and
`PrintRestoreGraph` (export.print_graph)."""

__all__ = ["export_all", "field_parity", "restore_parity", "print_parity", "RestoreGraph", "ProjectGraph",
           "FieldGraph", "PrintRestoreGraph"]

_WHERE = {"export_all": "onnx_export", "field_parity": "parity", "restore_parity": "parity",
          "print_parity": "parity", "RestoreGraph": "models", "ProjectGraph": "models", "FieldGraph": "models",
          "PrintRestoreGraph": "print_graph"}


def __getattr__(name):
    from importlib import import_module
    if name in _WHERE:
        return getattr(import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
