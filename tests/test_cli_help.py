"""Every option and argument of every `handle-drake` sub-command says what it does in --help."""

from __future__ import annotations

import argparse

from handle_drake.cli import build_parser


def _commands(parser: argparse.ArgumentParser, prefix: str = "handle-drake"):
    """(command line, parser) for the parser and each sub-command, recursively."""
    yield prefix, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _commands(sub, f"{prefix} {name}")


def _undocumented(parser: argparse.ArgumentParser) -> list[str]:
    missing = []
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        if action.help == argparse.SUPPRESS:
            continue
        if not (action.help or "").strip():
            missing.append("/".join(action.option_strings) or action.dest)
    return missing


def test_every_option_of_every_subcommand_has_help_text():
    commands = dict(_commands(build_parser()))
    # the walk sees the nested commands (midi's own sub-commands) and the known options
    assert {"handle-drake inhand", "handle-drake babble", "handle-drake synergies",
            "handle-drake midi write-scenarios"} <= commands.keys()
    missing = {line: names for line, parser in commands.items()
               if (names := _undocumented(parser))}
    assert not missing, f"options without help text: {missing}"


def test_the_check_sees_an_option_without_help():
    parser = argparse.ArgumentParser()
    parser.add_argument("--documented", help="does a thing")
    parser.add_argument("--bare")
    assert _undocumented(parser) == ["--bare"]
