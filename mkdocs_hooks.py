"""MkDocs hook: the API reference's CLI page gets `rllib --help` of every subcommand, taken from
the parser itself (`rllib_asor.cli.main.build_parser`), so the page cannot fall behind the code."""

from __future__ import annotations

import argparse
import os

MARKER = "<!-- rllib-help -->"


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:  # argparse keeps subcommands only here
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _sections(parser: argparse.ArgumentParser, name: str) -> list[str]:
    out = [f"## `{name}`", "", "```text", parser.format_help().rstrip(), "```", ""]
    for sub, sub_parser in _subparsers(parser).items():
        out += _sections(sub_parser, f"{name} {sub}")
    return out


def cli_help_markdown() -> str:
    """Every `rllib ... --help` text as markdown sections, wrapped at 100 columns."""
    from rllib_asor.cli.main import build_parser

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps at the terminal's width
    try:
        return "\n".join(_sections(build_parser(), "rllib"))
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


def on_page_markdown(markdown: str, **_: object) -> str:
    """Replace the marker with the generated help (MkDocs calls this for every page)."""
    return markdown.replace(MARKER, cli_help_markdown()) if MARKER in markdown else markdown
