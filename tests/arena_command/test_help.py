"""The `arena` command's help pages: descriptions reflowed, none lost."""

from __future__ import annotations

import re

import click
import typer

from arena_command import app
from tests.cli_runner import CliRunner

BOX = re.compile(r"[╭╮╰╯│─]")


def _commands(command: click.Command, path: list[str]):
    yield path, command
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, [*path, name])


def _help(path: list[str]) -> str:
    return CliRunner().invoke(app, [*path, "--help"], terminal_width=100).output


def test_every_command_describes_itself_in_paragraphs_its_page_shows_whole() -> None:
    commands = list(_commands(typer.main.get_command(app), []))
    assert len(commands) > 40  # the whole tree, not its first level only
    for path, command in commands:
        if not command.help:
            continue
        # A paragraph is one line: the terminal wraps it, not the source's line breaks.
        assert all("\n" not in p for p in command.help.split("\n\n")), path
        shown = " ".join(BOX.sub(" ", _help(path)).split())
        assert " ".join(command.help.split("\n\n")[0].split()) in shown, path


def test_a_command_list_fills_its_column_before_it_wraps() -> None:
    rows = [BOX.sub("", line).strip() for line in _help(["admin"]).splitlines()]
    audit = next(i for i, row in enumerate(rows) if row.startswith("audit "))
    # The docstring breaks its first line after "the first record that".
    assert rows[audit + 1].startswith("or the first record that differs.")
