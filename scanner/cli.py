"""Command-line options of the scanner-side commands (`sheet`, `simulate`, `scan`, `bench scan`).

Kept torch-free and import-light: the work is imported lazily when a command runs."""
from __future__ import annotations

__all__ = ["add_commands", "add_bench_commands"]


def add_commands(sub) -> None:
    """Add the scanner's subcommands to the top-level subparsers `sub`."""


def add_bench_commands(bsub) -> None:
    """Add `bench scan` to the `bench` subparsers `bsub`."""
