"""Team text reaches other people neutralised, in every sink: CSV cells (the public leaderboard
and the organisers' export), the organisers' terminal (Rich markup, control characters), their
log view (escape sequences made visible, forged headers told apart), and names that refuse
what would disguise them. Each test reproduces a case of issue 23."""

from __future__ import annotations

import csv
import io

import pytest
from rich.console import Console

from arena.neutralise.spreadsheet import cell
from arena.terminal import print_rows
from tests.server.api.test_api_submissions import upload, zip_bytes
from tests.server.builders import (
    evaluate_failing_everywhere,
    make_team,
    queued_submission,
    seed_scored,
)

FORMULA = '=HYPERLINK("http://127.0.0.1/x","click")'
MARKUP = "lane [/] keeper [bold red]x"
ESCAPES = "\x1b]0;owned\x07\x1b]52;c;ZXZpbA==\x07"  # window title, clipboard write


def rows_of(text: str) -> list[list[str]]:
    return list(csv.reader(io.StringIO(text)))


@pytest.mark.parametrize("name", [FORMULA, "+1+1", "-2+3", "@SUM(A1)", "\tTAB", "\rCR"])
def test_a_formula_in_a_method_name_stays_text_in_the_public_csv(client, db, name):
    team, _ = make_team(db, "alpha")
    seed_scored(db, team, (0.5, 100.0, 0.1, 0.1), method_name=name)
    header, row = rows_of(client.get("/api/v1/leaderboard.csv?phase=final").text)
    assert row[header.index("method_name")] == "'" + name
    assert row[header.index("completion")] == "0.5"  # numbers are left alone


def test_the_organisers_export_defuses_formulas_too(arena, db):
    team, _ = make_team(db, "alpha")
    seed_scored(db, team, (0.5, 100.0, 0.1, 0.1), method_name=FORMULA)
    header, row = rows_of(arena("leaderboard", "export", "--phase", "final"))
    assert row[header.index("method_name")] == "'" + FORMULA


def test_numbers_and_plain_text_pass_unchanged():
    assert [cell(v) for v in (-0.5, "-0.5", "1e-3", "lane keeper", 3)] == [
        -0.5,
        "-0.5",
        "1e-3",
        "lane keeper",
        3,
    ]


def test_markup_in_a_method_name_neither_crashes_nor_styles_a_terminal_table():
    buffer = io.StringIO()
    terminal = Console(file=buffer, force_terminal=True, width=200, color_system=None)
    print_rows(terminal, ("id", "method"), [(1, MARKUP), (2, ESCAPES + "x")], title=MARKUP)
    shown = buffer.getvalue()
    assert "lane [/] keeper [bold red]x" in shown
    assert "\x1b]" not in shown and "\x07" not in shown


def test_admin_submissions_list_on_a_terminal_shows_markup_as_text(arena, db, monkeypatch):
    import server.commands.submissions

    team, _ = make_team(db, "alpha")
    seed_scored(db, team, (0.5, 100.0, 0.1, 0.1), method_name=MARKUP)
    buffer = io.StringIO()
    terminal = Console(file=buffer, force_terminal=True, width=300, color_system=None)
    monkeypatch.setattr(server.commands.submissions, "console", terminal)
    arena("submissions", "list")
    assert MARKUP in buffer.getvalue()


def test_the_organisers_log_view_shows_escape_sequences_and_marks_the_agents_lines(
    arena,
    db,
    settings,
):
    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team, phase="final")
    forged = "=== cruise_000 (cruise): done reached_goal"
    evaluate_failing_everywhere(db, settings, sid, log=f"{ESCAPES}hello\n{forged}\n")
    output = arena("submissions", "logs", str(sid))
    assert "\x1b" not in output and "\x07" not in output
    assert "\\x1b]0;owned\\x07" in output
    assert f"| {forged}" in output
    headers = [line for line in output.splitlines() if line.startswith("=== ")]
    assert len(headers) == 3 and all("reached_goal" not in line for line in headers)


@pytest.mark.parametrize(
    "name",
    [
        "alpha\u202eahpla",  # right-to-left override
        "al\u200bpha",  # zero-width space
        "alpha\u2066",  # left-to-right isolate
        "\u3164alpha",  # Hangul filler: renders as nothing
        "alpha\x1b[2J",  # an escape sequence
    ],
)
def test_names_that_could_pass_for_others_are_refused_at_upload(client, db, name):
    _, token = make_team(db, "alpha")
    payload = zip_bytes({"policy.py": b"class Policy: pass\n"})
    response = upload(client, token, payload, method=name)
    assert response.status_code == 422
    assert "method_name: character" in response.json()["detail"]
    assert "not allowed in a name" in response.json()["detail"]


@pytest.mark.parametrize("name", ["alpha\n", "alpha\u202e", "al\u200bpha", "alpha\x1b[2J"])
def test_team_names_hold_no_control_bidi_or_invisible_character(db, name):
    from server.services import teams
    from server.services.errors import InvalidInput

    with db.session() as session, pytest.raises(InvalidInput):
        teams.create_team(session, name)
