"""Lazy command runners: the CLI's parsers stay import-light; a command's module is imported when it runs."""
from __future__ import annotations

import importlib

__all__ = ["lazy_command"]


def lazy_command(module: str, func: str):
    """A `func(args)` that imports `module` on first call and runs its `func(args)`."""
    def go(args):
        return getattr(importlib.import_module(module), func)(args)
    return go
