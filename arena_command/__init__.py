"""The ``arena`` command, the composition root above every layer: each part of the system
contributes its own Typer app and this package mounts them, so no layer imports one above it.

The area CLIs keep their imports light at module level so ``arena --help`` stays fast; heavy work
(SUMO, Docker, the database) is imported inside the commands.
"""

from __future__ import annotations

import inspect

import typer

from evaluator.cli import app as evaluator_app
from evaluator.sandbox.cli import sandbox_app
from evaluator.stacks_cli import stacks_app
from scenarios.cli import app as scenarios_app
from scenarios.dataset.cli import app as dataset_app
from server.commands import (
    audit,
    database,
    leaderboard,
    phases,
    runs,
    service,
    status,
    submissions,
    teams,
)
from submissions.cli import init_agent, submission_app


def admin_app() -> typer.Typer:
    """`arena admin`: the service's resources, one module each in `server/commands/`."""
    admin = typer.Typer(no_args_is_help=True)
    # Commands of their own, straight under `arena admin`.
    for commands in (runs.app, audit.app, status.app):
        admin.add_typer(commands)
    admin.add_typer(teams.app, name="teams", help="Teams and their API tokens.")
    admin.add_typer(submissions.app, name="submissions", help="Inspect and act on submissions.")
    admin.add_typer(leaderboard.app, name="leaderboard", help="Export the leaderboard.")
    admin.add_typer(database.app, name="db", help="The database schema.")
    admin.add_typer(phases.app, name="phases", help="Competition phases: suites, dates, quotas.")
    return admin


app = typer.Typer(
    name="arena",
    help="Driving Arena: evaluate driving agents and run the competition service.",
    no_args_is_help=True,
    pretty_exceptions_show_locals=False,
)
app.add_typer(scenarios_app, name="scenarios", help="Build, list, draw and verify scenario suites.")
app.add_typer(dataset_app, name="dataset", help="Build the offline-learning dataset (Minari).")
app.add_typer(submission_app, name="submission", help="Pack and check a submission zip.")
app.add_typer(sandbox_app, name="sandbox", help="The agent sandbox: runtime image, leftovers.")
app.add_typer(stacks_app, name="stacks", help="Organiser stacks: wheel sets agents build on.")
app.add_typer(admin_app(), name="admin", help="Organiser administration of the service.")
# `arena evaluate|score|replay` and `arena up|worker|serve` sit at the top level.
app.add_typer(evaluator_app)
app.add_typer(service.app)
app.command("init")(init_agent)


def _reflowed(doc: str) -> str:
    """``doc`` with each paragraph on one line: the docstrings wrap at 100 columns in the source,
    and Typer's Rich help keeps every line break of a paragraph, so a command list broke
    mid-sentence. Paragraphs (blank lines) stay apart."""
    paragraphs = inspect.cleandoc(doc).split("\n\n")
    return "\n\n".join(" ".join(p.split()) for p in paragraphs)


def _reflow_help(typer_app: typer.Typer) -> None:
    """Give every command of the tree its docstring reflowed as its help (Typer's Markdown mode
    would reflow too, but cuts long names and code in narrow columns with an ellipsis)."""
    for command in typer_app.registered_commands:
        if command.help is None and command.callback is not None and command.callback.__doc__:
            command.help = _reflowed(command.callback.__doc__)
    for group in typer_app.registered_groups:
        _reflow_help(group.typer_instance)


_reflow_help(app)
