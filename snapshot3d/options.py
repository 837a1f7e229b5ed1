"""Typed dataclass configs and their command-line options, one-to-one (STYLE: configs are typed
dataclasses with a docstring per field; the CLI maps onto them). torch-free."""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import field

__all__ = ["config_field", "add_dataclass_options", "config_from_args"]


def config_field(default, help: str):
    """A dataclass field whose `help` is its documentation and its `--option` text."""
    return field(default=default, metadata={"help": help})


def add_dataclass_options(parser: argparse.ArgumentParser, cls, skip: tuple = ()) -> None:
    """One `--option` per field of dataclass `cls` (not those in `skip`), its help from the field's metadata;
    the parser's formatter adds the default."""
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        flag = "--" + f.name.replace("_", "-")
        help_ = (f.metadata.get("help", "") or " ").replace("%", "%%")   # plain text, not an argparse template
        if f.type in (bool, "bool"):
            parser.add_argument(flag, dest=f.name, action=argparse.BooleanOptionalAction, default=f.default, help=help_)
        elif f.type in (tuple, "tuple"):  # one or more values of the default's element type
            typ = type(f.default[0]) if f.default else str
            parser.add_argument(flag, dest=f.name, nargs="+", type=typ, default=f.default, help=help_)
        else:
            typ = {"int": int, "float": float, int: int, float: float}.get(f.type, str)
            parser.add_argument(flag, dest=f.name, type=typ, default=f.default, help=help_)


def config_from_args(cls, args, **override):
    """An instance of dataclass `cls` from parsed options (fields missing from `args` keep their default)."""
    values = {f.name: getattr(args, f.name) for f in dataclasses.fields(cls) if hasattr(args, f.name)}
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return cls(**{**values, **override})
