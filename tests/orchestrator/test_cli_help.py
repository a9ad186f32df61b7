"""Every option of every `linkevo` command says what it does and its default."""

from __future__ import annotations

import argparse

from linkevo.orchestrator.cli import build_parser, main


def all_parsers(parser: argparse.ArgumentParser, name: str = "linkevo"):
    """Yields (name, parser) for the parser and every subcommand below it."""
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from all_parsers(sub, f"{name} {sub_name}")


def test_every_option_has_help_showing_its_default():
    missing = []
    for name, parser in all_parsers(build_parser()):
        formatter = parser._get_formatter()
        for action in parser._actions:
            if not action.option_strings or action.help == argparse.SUPPRESS:
                continue
            if isinstance(action, argparse._HelpAction | argparse._VersionAction):
                continue
            text = formatter._get_help_string(action) or ""
            if not action.help or "default" not in text:
                missing.append(f"{name} {action.option_strings[0]}")
    assert missing == []


def test_version_prints_the_installed_version(capsys):
    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("linkevo ") and out.strip() != "linkevo"
