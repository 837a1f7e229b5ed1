"""Options of `snapshot3d serve` (the torch-free `ServeConfig` dataclass, one option per field)."""
from __future__ import annotations

from snapshot3d.lazy import lazy_command as _run
from snapshot3d.options import add_dataclass_options

from .common import add_command as _add

__all__ = ["add_commands"]


def add_commands(sub) -> None:
    """Add serve to the top-level subparsers `sub`."""
    from snapshot3d.viewer.serve_config import ServeConfig  # a torch-free dataclass

    sv = _add(sub, "serve", "the scan-and-view API and the phone page: upload a photo, turn the scene (no torch)",
              _run("snapshot3d.viewer.commands", "serve_command"))
    add_dataclass_options(sv, ServeConfig)
