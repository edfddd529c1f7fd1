"""`arena admin submissions ...`: inspect and act on submissions (`server/services/submissions.py`;
the lost work a requeue sends again, `server/services/admin.py`)."""

from __future__ import annotations

import json
import sys
from typing import Annotated

import typer

from arena.figures import metric_text
from arena.neutralise.console import plain
from arena.neutralise.log_view import quoted
from arena.terminal import print_rows
from server.commands.console import console
from server.commands.context import AdminContext, SubmissionId, or_fail
from server.commands.submission_detail import detail_lines

app = typer.Typer(no_args_is_help=True)


def _status_text(row, rerunning: set[int]) -> str:
    """A scored submission with a new attempt under way keeps its old score meanwhile: say so,
    instead of "scored" next to 10/128."""
    if row.status == "scored" and row.id in rerunning:
        return "scored (re-run running)"
    return str(row.status)


@app.command("list")
def submissions_list(
    limit: Annotated[int, typer.Option(min=1, max=10_000)] = 50,
    as_json: Annotated[bool, typer.Option("--json", help="The rows as a JSON list.")] = False,
) -> None:
    """The latest submissions with status, progress and metrics."""
    # deferred: CLI start-up time
    from server.services import submissions

    ctx = AdminContext()
    with ctx.db.read_session() as session:
        rows = submissions.list_submissions(session, limit=limit)
        rerunning = submissions.rerunning(session)
    if as_json:
        sys.stdout.write(json.dumps([r.model_dump(mode="json") for r in rows], indent=2) + "\n")
        return
    print_rows(
        console,
        ("id", "team", "phase", "track", "method", "status", "progress", "completion", "time"),
        [
            (
                r.id,
                r.team,
                r.phase,
                r.track,
                r.method_name,
                _status_text(r, rerunning),
                f"{r.progress.done}/{r.progress.total}"
                + (" quarters" if r.progress.unit == "quarters" else ""),
                metric_text("completion", r.metrics and r.metrics.completion),
                metric_text("time", r.metrics and r.metrics.time),
            )
            for r in rows
        ],
        numeric=("id", "completion", "time"),
    )


@app.command("show")
def submissions_show(
    submission_id: SubmissionId,
    as_json: Annotated[
        bool, typer.Option("--json", help="One JSON document (detail and every attempt).")
    ] = False,
) -> None:
    """Everything about a submission, including per-scenario results (organisers only)."""
    # deferred: CLI start-up time
    from server.services import standing, submissions

    ctx = AdminContext()
    with ctx.db.read_session() as session:
        submission = or_fail(lambda: submissions.get_submission(session, submission_id))
        view = standing.team_view(session, ctx.settings.service, ctx.settings.sandbox, submission)
        # The organisers' own count: a team sees a hidden phase's run only in quarters.
        progress = submissions.exact_progress(session, submission)
        runs = [
            (
                run.attempt,
                run.status,
                run.worker,
                run.scoring_profile,
                run.error,
                sorted(
                    (r.scenario_id, r.episode, r.family, r.status, r.reason, r.steps)
                    for r in run.results
                ),
            )
            for run in submission.runs
        ]
        # A seed's evaluation is a run of its own, not a retry: said beside its number.
        which = {
            run.attempt: f" (seed {run.training.seed} of {run.training.seeds})"
            for run in submission.runs
            if run.training is not None and run.training.seeds > 1
        }
    columns = ("scenario", "episode", "family", "status", "reason", "steps")
    if as_json:
        document = view.model_dump(mode="json")
        document["attempts"] = [
            {
                "attempt": attempt,
                "status": status,
                "worker": worker,
                "scoring_profile": profile,
                "error": error,
                "results": [dict(zip(columns, row, strict=True)) for row in results],
            }
            for attempt, status, worker, profile, error, results in runs
        ]
        sys.stdout.write(json.dumps(document, indent=2) + "\n")
        return
    for name, value in detail_lines(view, progress):
        console.print(f"{name}: {plain(value)}", markup=False, highlight=False)
    for attempt, status, worker, profile, error, results in runs:
        title = (
            f"attempt {attempt}{which.get(attempt, '')}: {status} ({profile}) "
            f"{worker or ''} {error or ''}"
        ).strip()
        print_rows(console, columns, results, title=title, numeric=("episode", "steps"))


@app.command("logs")
def submissions_logs(submission_id: SubmissionId) -> None:
    """The agent's output per scenario, with scenario ids, in every phase (organisers only: in a
    hidden phase the team never sees it)."""
    # deferred: CLI start-up time
    from server.services import submissions

    ctx = AdminContext()
    with ctx.db.read_session() as session:
        submission = or_fail(lambda: submissions.get_submission(session, submission_id))
        view = submissions.logs(session, submission, organiser=True)
    for entry in view.scenarios:
        episode = f" episode {entry.episode}" if entry.episode else ""
        typer.echo(
            plain(
                f"=== {entry.scenario_id}{episode} ({entry.family}): {entry.status} {entry.reason}"
            )
        )
        # The agent's bytes: escape sequences shown, not run; each line marked as the agent's so
        # none can pass for one of these headers.
        typer.echo(quoted(entry.log_tail))


@app.command("cancel")
def submissions_cancel(submission_id: SubmissionId) -> None:
    """Stop a submission: queued work is revoked, running sandboxes are killed."""
    # deferred: CLI start-up time
    from server.services import submissions

    ctx = AdminContext()
    or_fail(lambda: submissions.cancel(ctx.db, ctx.queue, submission_id))
    console.print(f"submission {submission_id} cancelled")


@app.command("disqualify")
def submissions_disqualify(
    submission_id: SubmissionId,
    reason: Annotated[str, typer.Option(help="Why: shown to the team (required).")],
) -> None:
    """Take a submission off the leaderboard for good, telling its team why."""
    # deferred: CLI start-up time
    from server.services import submissions

    ctx = AdminContext()
    or_fail(lambda: submissions.disqualify(ctx.db, ctx.queue, submission_id, reason))
    console.print(f"submission {submission_id} disqualified")


@app.command("requeue")
def submissions_requeue(submission_id: SubmissionId) -> None:
    """Send an unfinished submission's lost work again (lost messages, dead worker); an
    evaluation a worker is still renewing is healthy and is left alone. A training seed lost on
    our side trains again (the other seeds keep what they did)."""
    # deferred: CLI start-up time
    from server.services import admin

    ctx = AdminContext()
    console.print(or_fail(lambda: admin.requeue(ctx.db, ctx.settings, ctx.queue, submission_id)))
