"""Every option of every command shows its default in `--help` (issue 39: the README says each
command's --help lists its options with their defaults; `emulate-servo --protocol` and
`demo --seed` showed none)."""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator

import pytest

from servant_core.cli import build_parser


def commands() -> Iterator[argparse.ArgumentParser]:
    """`servant` and each (sub)command's parser, every option registered."""
    stack: list[argparse.ArgumentParser] = [build_parser(lazy=False)]
    while stack:
        parser = stack.pop()
        yield parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                stack += list(action.choices.values())


def with_values() -> Iterator[tuple[argparse.ArgumentParser, argparse.Action]]:
    """(command, option) for each option with a default worth showing: not None, not a flag's
    False, and not an empty list (no value either, as `--image` with no pictures)."""
    for parser in commands():
        for action in parser._actions:
            default = action.default
            if not action.option_strings or isinstance(action, argparse._HelpAction):
                continue
            if default is None or default is False or default is argparse.SUPPRESS:
                continue
            if isinstance(default, list | tuple) and not default:
                continue
            yield parser, action


def help_of(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """What `--help` says of `action`: its lines of the help, without its name and choices."""
    lines = parser.format_help().splitlines()
    name = action.option_strings[0]
    start = next(
        i for i, line in enumerate(lines) if re.match(rf"\s+{re.escape(name)}([ ,]|$)", line)
    )
    block = [lines[start]]
    for line in lines[start + 1 :]:
        if not line.strip() or re.match(r"\s{1,4}-", line):
            break
        block.append(line)
    text = " ".join(" ".join(block).split())
    return re.sub(r"\{[^}]*\}", "", text).replace(name, "", 1)


def shown_as(default: object) -> set[str]:
    """How a default may be written in a help text."""
    if isinstance(default, list | tuple):
        return {",".join(map(str, default)), ", ".join(map(str, default))}
    if isinstance(default, float):
        return {str(default), f"{default:g}"}
    return {str(default)}


@pytest.mark.parametrize(
    ("parser", "action"),
    list(with_values()),
    ids=lambda x: x.prog if isinstance(x, argparse.ArgumentParser) else x.option_strings[0],
)
def test_help_shows_every_default(
    parser: argparse.ArgumentParser, action: argparse.Action, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("COLUMNS", "400")  # each option's help on as few lines as can be
    said = help_of(parser, action)
    match = re.search(r"default\b[^)]*", said)
    assert match, f"{parser.prog} {action.option_strings[0]}: no default in {said!r}"
    assert any(value in match.group() for value in shown_as(action.default)), (
        f"{parser.prog} {action.option_strings[0]}: default {action.default!r} not in {said!r}"
    )


def test_the_commands_are_all_walked() -> None:
    progs = {parser.prog for parser in commands()}
    assert {"servant demo", "servant emulate-servo", "servant eval audio"} <= progs
    assert len(list(with_values())) > 30
