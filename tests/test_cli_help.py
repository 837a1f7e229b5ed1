"""Every command's and subcommand's --help text formats (in process: the parsers import no torch)."""
import argparse

from snapshot3d.cli import build_parser


def _parsers(parser, name="snapshot3d"):
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub, p in action.choices.items():
                yield from _parsers(p, f"{name} {sub}")


def test_every_help_text_formats():
    seen = []
    for name, parser in _parsers(build_parser()):
        text = parser.format_help()   # a stray % in an option's help raises here
        assert text.startswith("usage:"), name
        seen.append(name)
    assert {"snapshot3d fit", "snapshot3d bench capture-background", "snapshot3d decode"} <= set(seen), seen


def test_a_percent_sign_in_an_option_s_help_is_text():
    (help_,) = [p.format_help() for name, p in _parsers(build_parser()) if name == "snapshot3d fit"]
    assert "2.8% outside" in " ".join(help_.split())
