"""The commands' one console (server/commands/console.py): written to a pipe, plain text without
a colour code, rows a line each, and progress as bounded plain lines on stderr."""

from __future__ import annotations

import os
import subprocess

import pytest

from server.commands.console import progress
from tests.server.builders import make_team, queued_submission
from tests.server.live import ARENA
from tests.server.worker.test_evaluation_flow import run_everything, start

ESCAPE = "\x1b"


def arena_piped(*args: str) -> subprocess.CompletedProcess[str]:
    """``arena admin ...`` as its own process with stdout and stderr pipes, under the name of a
    colour terminal: only the pipe tells it to write plain text."""
    env = {key: value for key, value in os.environ.items() if "COLOR" not in key}
    env["TERM"] = "xterm-256color"
    return subprocess.run(
        [*ARENA, "admin", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )


def test_a_long_command_piped_says_its_progress_on_stderr_at_a_bounded_rate(capsys):
    """`arena admin audit | tee` once printed nothing for minutes: piped, its progress is plain
    lines on stderr, the first episode and the last at once, between them one per interval."""
    with progress("submission 7", "episodes re-run") as step:
        for done in range(1, 129):
            step(done, 128)
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.splitlines() == [
        "submission 7: 1/128 episodes re-run",
        "submission 7: 128/128 episodes re-run",
    ]


# Three real `arena` processes, each importing the whole command tree (about 5 s of CPU): the fast
# tier starts none, so this runs with the integration tier.
@pytest.mark.integration
def test_piped_the_commands_write_plain_lines_and_progress_apart(arena, db, settings):
    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, sid))
    rescored = arena_piped("rescore", "--all")
    assert rescored.returncode == 0, rescored.stderr
    # The results alone on stdout, a header and a tab-separated row; progress on stderr.
    assert ESCAPE not in rescored.stdout + rescored.stderr
    header, row = rescored.stdout.splitlines()
    assert header.split("\t")[:4] == ["submission", "attempt", "phase", "profile"]
    assert row.split("\t")[:3] == [str(sid), "1", "final"]
    assert rescored.stderr.splitlines() == ["re-scoring: 1/1 runs"]
    listed = arena_piped("submissions", "list")
    assert ESCAPE not in listed.stdout and listed.stdout.splitlines()[1].startswith(f"{sid}\t")
    # A refusal: its one error line, without the colour it has on a terminal, and exit status 1.
    refused = arena_piped("submissions", "show", "999")
    assert (refused.returncode, refused.stdout) == (1, "error: no submission 999\n")
