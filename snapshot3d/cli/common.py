"""What every command group's parser shares: the help formatter, the one way a command is added, and the
option helps several commands repeat. Import-light (no torch, no numpy)."""
from __future__ import annotations

import argparse

__all__ = ["Formatter", "add_command", "hosts_help", "DEVICE_HELP"]

DEVICE_HELP = "where training runs: auto (CUDA when present), cpu or cuda"


class Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's help ends with its default."""

    def _get_help_string(self, action):
        if action.default in (None, False) or action.help in (None, argparse.SUPPRESS) or "%(default)" in action.help:
            return action.help
        return super()._get_help_string(action)


def hosts_help() -> str:
    from snapshot3d.scanner.backgrounds import BACKGROUND_NAMES
    return ("host photo: an image file, or builtin:NAME, a bundled photo (NAME one of "
            + ", ".join(BACKGROUND_NAMES + ("grace_hopper",)) + ")")


def add_command(sub, name: str, help: str, func, **kw) -> argparse.ArgumentParser:
    """A parser for command `name` under the subparsers `sub` that runs `func(args)` (None: a group)."""
    p = sub.add_parser(name, help=help, description=help[:1].upper() + help[1:] + ".", formatter_class=Formatter, **kw)
    p.set_defaults(func=func)
    return p
