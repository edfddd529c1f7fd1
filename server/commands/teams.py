"""`arena admin teams ...`: teams and their API tokens (`server/services/teams.py`; deleting
one, `server/services/removal.py`)."""

from __future__ import annotations

from typing import Annotated

import typer

from arena.neutralise.console import safe
from arena.terminal import print_rows
from server.commands.console import console
from server.commands.context import AdminContext, or_fail
from server.commands.removal import delete_after_asking

app = typer.Typer(no_args_is_help=True)


@app.command("create")
def teams_create(name: str) -> None:
    """Create a team and print its API token (shown once)."""
    # deferred: CLI start-up time
    from server.services import teams

    ctx = AdminContext()
    with ctx.db.session() as session:
        team, token = or_fail(lambda: teams.create_team(session, name))
    console.print(
        f"team [bold]{safe(team.name)}[/bold] (id {team.id}) created; its token, shown once:"
    )
    # Alone on its line, never wrapped: copy it or take it with `tail -n 1`.
    print(token)


@app.command("list")
def teams_list(
    as_json: Annotated[bool, typer.Option("--json", help="The rows as a JSON list.")] = False,
) -> None:
    """Every team with its number of submissions."""
    # deferred: CLI start-up time
    from server.services import teams

    ctx = AdminContext()
    with ctx.db.read_session() as session:
        rows = teams.list_teams(session)
    print_rows(
        console,
        ("id", "team", "submissions", "created"),
        [(r.id, r.name, r.submissions, f"{r.created_at:%Y-%m-%d %H:%M}") for r in rows],
        as_json=as_json,
        numeric=("id", "submissions"),
    )


@app.command("rotate-token")
def teams_rotate(name: str) -> None:
    """Revoke the team's tokens and print a new one."""
    # deferred: CLI start-up time
    from server.services import teams

    ctx = AdminContext()
    with ctx.db.session() as session:
        team = or_fail(lambda: teams.get_team(session, name))
        token = teams.rotate_token(session, team)
    console.print(f"new token for [bold]{safe(name)}[/bold] (the old ones are revoked):")
    print(token)


@app.command("delete")
def teams_delete(
    name: Annotated[str, typer.Argument(help="The team.")],
    yes: Annotated[bool, typer.Option("--yes", help="Do not ask for confirmation.")] = False,
) -> None:
    """Delete a team, its tokens and every submission it made (uploads, results, scores,
    records, trained models)."""
    # deferred: CLI start-up time
    # deferred: CLI start-up time
    from server.services import removal

    delete_after_asking(name, yes, removal.team_removal, removal.remove_team)
