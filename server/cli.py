"""`arena admin ...` (organisers) and the service commands `arena up`, `arena serve`,
`arena worker`. Thin: every command calls the same service functions as the API."""

from __future__ import annotations

import json
import math
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated

import typer

from arena.figures import METRICS, interval_text, metric_text
from arena.neutralise.console import plain, safe
from arena.neutralise.log_view import quoted
from arena.terminal import make_console, print_rows
from server.tracks import Track

admin_app = typer.Typer(no_args_is_help=True)
service_app = typer.Typer(no_args_is_help=True)
teams_app = typer.Typer(no_args_is_help=True, help="Teams and their API tokens.")
submissions_app = typer.Typer(no_args_is_help=True, help="Inspect and act on submissions.")
leaderboard_app = typer.Typer(no_args_is_help=True, help="Export the leaderboard.")
db_app = typer.Typer(no_args_is_help=True, help="The database schema.")
phases_app = typer.Typer(no_args_is_help=True, help="Competition phases: suites, dates, quotas.")
admin_app.add_typer(teams_app, name="teams")
admin_app.add_typer(submissions_app, name="submissions")
admin_app.add_typer(leaderboard_app, name="leaderboard")
admin_app.add_typer(db_app, name="db")
admin_app.add_typer(phases_app, name="phases")

console = make_console()
# The API's bound (server.api.deps.MAX_ROW_ID): a larger id is a usage error, not a driver's
# overflow traceback.
MAX_ID = 2**31 - 1
# [s] between the plain progress lines a long command writes to a pipe.
PLAIN_PROGRESS_S = 10.0
SubmissionId = Annotated[int, typer.Argument(help="Submission id.", min=1, max=MAX_ID)]


class _Context:
    """Settings, database and task queue, built on first use by a command."""

    def __init__(self) -> None:
        # deferred: CLI start-up time
        from arena.config import get_settings
        from server.core.artifacts import artifact_store
        from server.core.db import Database
        from server.core.migrate import DatabaseNotReady, check_database_ready
        from server.core.queue import TaskQueue

        self.settings = get_settings()
        try:
            check_database_ready(self.settings.storage.resolved_database_url)
        except DatabaseNotReady as exc:
            raise _fail(exc) from None
        self.db = Database(self.settings.storage.resolved_database_url)
        self.queue = TaskQueue(self.settings)
        self.store = artifact_store(self.settings.storage, self.db)


def _fail(exc: Exception) -> typer.Exit:
    console.print(f"[red]error:[/red] {safe(getattr(exc, 'message', exc))}")
    return typer.Exit(1)


def _run(action):
    # deferred: CLI start-up time
    from server.services.errors import ServiceError
    from server.status import IllegalTransition

    try:
        return action()
    except (ServiceError, IllegalTransition) as exc:
        raise _fail(exc) from None


# --- db ---------------------------------------------------------------------------------------


@db_app.command("upgrade")
def db_upgrade(revision: str = "head") -> None:
    """Apply the Alembic migrations to the configured database."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from server.core.migrate import current_revision, upgrade_database

    url = get_settings().storage.resolved_database_url
    upgrade_database(url, revision)
    console.print(f"database at revision [bold]{current_revision(url)}[/bold]")


# --- teams ------------------------------------------------------------------------------------


@teams_app.command("create")
def teams_create(name: str) -> None:
    """Create a team and print its API token (shown once)."""
    # deferred: CLI start-up time
    from server.services import teams

    ctx = _Context()
    with ctx.db.session() as session:
        team, token = _run(lambda: teams.create_team(session, name))
    console.print(
        f"team [bold]{safe(team.name)}[/bold] (id {team.id}) created; its token, shown once:"
    )
    # Alone on its line, never wrapped: copy it or take it with `tail -n 1`.
    print(token)


@teams_app.command("list")
def teams_list(
    as_json: Annotated[bool, typer.Option("--json", help="The rows as a JSON list.")] = False,
) -> None:
    """Every team with its number of submissions."""
    # deferred: CLI start-up time
    from server.services import teams

    ctx = _Context()
    with ctx.db.read_session() as session:
        rows = teams.list_teams(session)
    print_rows(
        console,
        ("id", "team", "submissions", "created"),
        [(r.id, r.name, r.submissions, f"{r.created_at:%Y-%m-%d %H:%M}") for r in rows],
        as_json=as_json,
        numeric=("id", "submissions"),
    )


@teams_app.command("rotate-token")
def teams_rotate(name: str) -> None:
    """Revoke the team's tokens and print a new one."""
    # deferred: CLI start-up time
    from server.services import teams

    ctx = _Context()
    with ctx.db.session() as session:
        team = _run(lambda: teams.get_team(session, name))
        token = teams.rotate_token(session, team)
    console.print(f"new token for [bold]{safe(name)}[/bold] (the old ones are revoked):")
    print(token)


# --- submissions ------------------------------------------------------------------------------


def _status_text(row, rerunning: set[int]) -> str:
    """A scored submission with a new attempt under way keeps its old score meanwhile: say so,
    instead of "scored" next to 10/128."""
    if row.status == "scored" and row.id in rerunning:
        return "scored (re-run running)"
    return str(row.status)


def _active_submissions(session) -> set[int]:
    # deferred: CLI start-up time
    from sqlalchemy import select

    # deferred: CLI start-up time
    from server.models import EvaluationRun
    from server.status import ACTIVE_RUN

    active = select(EvaluationRun.submission_id).where(EvaluationRun.status.in_(list(ACTIVE_RUN)))
    return set(session.scalars(active))


@submissions_app.command("list")
def submissions_list(
    limit: Annotated[int, typer.Option(min=1, max=10_000)] = 50,
    as_json: Annotated[bool, typer.Option("--json", help="The rows as a JSON list.")] = False,
) -> None:
    """The latest submissions with status, progress and metrics."""
    # deferred: CLI start-up time
    from server.services import submissions

    ctx = _Context()
    with ctx.db.read_session() as session:
        rows = submissions.list_submissions(session, limit=limit)
        rerunning = _active_submissions(session)
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


@submissions_app.command("show")
def submissions_show(
    submission_id: SubmissionId,
    as_json: Annotated[
        bool, typer.Option("--json", help="One JSON document (detail and every attempt).")
    ] = False,
) -> None:
    """Everything about a submission, including per-scenario results (organisers only)."""
    # deferred: CLI start-up time
    from server.services import standing, submissions

    ctx = _Context()
    with ctx.db.read_session() as session:
        submission = _run(lambda: submissions.get_submission(session, submission_id))
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
    m = view.metrics
    for name, value in (
        ("submission", f"{view.id} by {view.team}: {view.method_name} ({view.track})"),
        ("phase", view.phase),
        ("status", f"{view.status} {view.status_reason}".strip()),
        ("progress", f"{progress.done}/{progress.total}"),
        ("submitted", _at(view.created_at)),
        ("timings", _timings(view)),
        ("rank", _rank_text(view.standing)),
        ("file", f"sha256 {view.file_sha256}, {view.file_size} bytes"),
        (
            "metrics",
            "-"
            if m is None
            else f"completion {metric_text('completion', m.completion)}"
            f"{_interval_text(view.completion_interval)}, time {metric_text('time', m.time)}, "
            f"humanness {metric_text('humanness', m.humanness)}, "
            f"rules {metric_text('rules', m.rules)}",
        ),
        ("episodes", f"{view.episodes_per_scenario} per reactive scenario"),
        *_seed_rows(view.seeds),
        *_manifest_rows(view.manifest, scored=m is not None),
    ):
        console.print(f"{name}: {plain(value)}", markup=False, highlight=False)
    for attempt, status, worker, profile, error, results in runs:
        title = (
            f"attempt {attempt}{which.get(attempt, '')}: {status} ({profile}) "
            f"{worker or ''} {error or ''}"
        ).strip()
        print_rows(console, columns, results, title=title, numeric=("episode", "steps"))


def _seed_rows(seeds) -> list[tuple[str, str]]:
    """A submission scored over several training seeds: their spread and each one's."""
    if seeds is None:
        return []
    each = ", ".join(f"{s.seed}: {metric_text('completion', s.completion)}" for s in seeds.per_seed)
    spread = seeds.ignores_seed or (
        f"completion from {metric_text('completion', seeds.completion_min)} "
        f"to {metric_text('completion', seeds.completion_max)} "
        f"(std {metric_text('completion', seeds.completion_std)})"
    )
    return [("seeds", f"{seeds.count}, {spread}; per seed {each}")]


def _timings(view) -> str:
    took = "" if view.duration_s is None else f", took {_duration(view.duration_s)}"
    return (
        f"queued {_at(view.queued_at)}, started {_at(view.started_at)}, "
        f"finished {_at(view.finished_at)}{took}"
    )


def _duration(seconds: float) -> str:
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m{secs:02d}s" if hours else f"{minutes}m{secs:02d}s"


def _rank_text(standing) -> str:
    if standing is None or standing.rank is None:
        return "not ranked"
    return (
        f"team ranks {standing.rank} of {standing.teams_ranked} "
        f"(with submission {standing.ranked_submission_id}); {standing.statistics}"
    )


def _manifest_rows(manifest, *, scored: bool) -> list[tuple[str, str]]:
    """The reproducibility manifest, in the lines of `submissions show` (docs/scoring.md)."""
    if manifest is None:
        why = "scored before manifests were kept" if scored else "not scored"
        return [("manifest", f"- ({why})")]
    software = "; ".join(
        f"arena {e.arena}, Python {e.python}, numpy {e.numpy}, SUMO {e.sumo}, {e.sandbox}"
        + (f", image {e.agent_image}" if e.agent_image else "")
        for e in manifest.environments
    )
    return [
        (
            "manifest",
            f"suite {manifest.suite} {manifest.suite_hash[:12]}, "
            f"{len(manifest.scenario_hashes)} scenarios, seeds {manifest.seeds_sha256[:12]}, "
            f"profile {manifest.profile} v{manifest.profile_version}, "
            f"model {_models_text(manifest)}",
        ),
        ("software", software or "-"),
    ]


def _models_text(manifest) -> str:
    """The trained model's sha256, or each training seed's."""
    if manifest.seed_models:
        return "; ".join(f"seed {m.seed} {m.model}" for m in manifest.seed_models)
    return manifest.model or "-"


def _interval_text(interval) -> str:
    return "" if interval is None else f" {interval_text(interval.low, interval.high)}"


@submissions_app.command("logs")
def submissions_logs(submission_id: SubmissionId) -> None:
    """The agent's output per scenario, with scenario ids, in every phase (organisers only: in a
    hidden phase the team never sees it)."""
    # deferred: CLI start-up time
    from server.services import submissions

    ctx = _Context()
    with ctx.db.read_session() as session:
        submission = _run(lambda: submissions.get_submission(session, submission_id))
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


@submissions_app.command("cancel")
def submissions_cancel(submission_id: SubmissionId) -> None:
    """Stop a submission: queued work is revoked, running sandboxes are killed."""
    # deferred: CLI start-up time
    from server.services import submissions

    ctx = _Context()
    _run(lambda: submissions.cancel(ctx.db, ctx.queue, submission_id))
    console.print(f"submission {submission_id} cancelled")


@submissions_app.command("disqualify")
def submissions_disqualify(
    submission_id: SubmissionId,
    reason: Annotated[str, typer.Option(help="Why: shown to the team (required).")],
) -> None:
    """Take a submission off the leaderboard for good, telling its team why."""
    # deferred: CLI start-up time
    from server.services import submissions

    ctx = _Context()
    _run(lambda: submissions.disqualify(ctx.db, ctx.queue, submission_id, reason))
    console.print(f"submission {submission_id} disqualified")


@submissions_app.command("requeue")
def submissions_requeue(submission_id: SubmissionId) -> None:
    """Send an unfinished submission's lost work again (lost messages, dead worker); an
    evaluation a worker is still renewing is healthy and is left alone. A training seed lost on
    our side trains again (the other seeds keep what they did)."""
    # deferred: CLI start-up time
    from server.services import admin

    ctx = _Context()
    console.print(_run(lambda: admin.requeue(ctx.db, ctx.settings, ctx.queue, submission_id)))


# --- rescore / rerun / status ------------------------------------------------------------------


@admin_app.command("rescore")
def rescore(
    submission_id: Annotated[
        int | None, typer.Argument(help="Submission id.", min=1, max=MAX_ID)
    ] = None,
    all_: Annotated[bool, typer.Option("--all", help="Every scored submission.")] = False,
    phase: Annotated[str | None, typer.Option(help="Every scored submission of a phase.")] = None,
    profile: Annotated[
        str | None,
        typer.Option(
            help="With --phase: make this the phase's scoring profile and re-score all of it "
            "(a leaderboard never ranks one submission by other formulas than the rest)."
        ),
    ] = None,
) -> None:
    """Recompute scores from the stored episode records (no simulation), each with the scoring
    profile of its phase."""
    # deferred: CLI start-up time
    from rich.progress import Progress

    # deferred: CLI start-up time
    from server.services import admin

    if sum((submission_id is not None, all_, phase is not None)) != 1:
        raise typer.BadParameter("give one of: a submission id, --phase NAME, --all")
    ctx = _Context()
    targets = _run(
        lambda: admin.rescore_targets(
            ctx.db, ctx.settings, submission_id=submission_id, phase=phase, profile=profile
        )
    )
    if not targets:
        raise _fail(ValueError("no scored evaluation to re-score"))
    if profile is not None:
        console.print(f"phase [bold]{phase}[/bold] is now scored with profile {profile}")
    rows = []
    with Progress(console=console, transient=True) as progress:
        task = progress.add_task("re-scoring", total=len(targets))
        for target in targets:
            used, metrics = _run(
                lambda target=target: admin.rescore_run(
                    ctx.db, ctx.settings.evaluation, ctx.store, target.run_id
                )
            )
            rows.append(
                (
                    target.submission_id,
                    target.attempt,
                    target.phase,
                    used,
                    *(metric_text(name, metrics[name]) for name in METRICS),
                )
            )
            progress.advance(task)
    print_rows(
        console,
        ("submission", "attempt", "phase", "profile", "completion", "time", "humanness", "rules"),
        rows,
        numeric=("submission", "attempt", "completion", "time", "humanness", "rules"),
    )


@admin_app.command("compare")
def compare(
    a: SubmissionId,
    b: SubmissionId,
    as_json: Annotated[bool, typer.Option("--json", help="The comparison as JSON.")] = False,
) -> None:
    """Two submissions side by side (hidden phases included): metrics with B - A and whether the
    completion intervals overlap, per family, and the episodes that ended differently."""
    from evaluator.compare import print_comparison
    from server.services import admin

    ctx = _Context()
    sides = [_run(lambda sid=sid: admin.comparison_side(ctx.db, sid)) for sid in (a, b)]
    print_comparison(console, *sides, as_json=as_json)


@admin_app.command("rerun")
def rerun(submission_id: SubmissionId) -> None:
    """Simulate a scored or failed submission again, as a new attempt (an offline one: every
    seed's trained model)."""
    # deferred: CLI start-up time
    from server.services import admin

    ctx = _Context()
    attempt = _run(lambda: admin.rerun(ctx.db, ctx.settings, ctx.queue, submission_id))
    console.print(f"submission {submission_id}: attempt {attempt} queued")


@contextmanager
def _episode_progress(what: str):
    """Progress of a long command on stderr, so that its results on stdout stay clean: a bar on
    a terminal; piped, a plain line at the first episode, then at most every PLAIN_PROGRESS_S
    (a pipe never sits silent for minutes, nor floods a log)."""
    from rich.progress import Progress

    err = make_console(stderr=True)
    if err.is_terminal:
        with Progress(console=err, transient=True) as bar:
            task = bar.add_task(what, total=None)
            yield lambda done, total: bar.update(task, completed=done, total=total)
        return
    said = -math.inf

    def line(done: int, total: int) -> None:
        nonlocal said
        if done == total or time.monotonic() - said >= PLAIN_PROGRESS_S:
            said = time.monotonic()
            print(f"{what}: {done}/{total} episodes re-run", file=sys.stderr, flush=True)

    yield line


@admin_app.command("audit")
def audit(
    submission_id: Annotated[
        int | None, typer.Argument(help="Submission id.", min=1, max=MAX_ID)
    ] = None,
    sample: Annotated[
        int | None,
        typer.Option(
            "--sample", min=1, max=1000, help="Audit N random leaderboard entries (nightly)."
        ),
    ] = None,
) -> None:
    """Re-run scored submissions from their manifests: bit-identical, or the first record that
    differs. Refuses, naming them, when the manifest's components differ here. Exits 1 unless
    every audit is bit-identical."""
    from server.services import audit as audits

    if (submission_id is None) == (sample is None):
        raise typer.BadParameter("give one submission id or --sample N")
    ctx = _Context()
    targets = [submission_id] if sample is None else audits.sample(ctx.db, sample)
    if not targets:
        raise _fail(ValueError("no leaderboard entry to audit"))
    clean = True
    print(
        f"auditing {len(targets)} submission(s): {', '.join(map(str, targets))}",
        file=sys.stderr,
        flush=True,
    )
    for target in targets:
        with _episode_progress(f"submission {target}") as step:
            report = _run(
                lambda target=target, step=step: audits.audit(
                    ctx.db,
                    ctx.store,
                    target,
                    intake=ctx.settings.intake,
                    config=ctx.settings.sandbox,
                    data_dir=ctx.settings.storage.resolved_data_dir,
                    progress=step,
                )
            )
        clean &= report.identical
        if report.refused:
            console.print(f"submission {target}: refused, the manifest's components differ:")
            for component in report.refused:
                console.print(f"  {component}", markup=False, highlight=False)
        elif report.difference is not None:
            console.print(
                f"submission {target}: differs after {report.compared} episode(s): "
                f"{report.difference}",
                markup=False,
                highlight=False,
            )
        else:
            console.print(f"submission {target}: bit-identical ({report.compared} episodes)")
    if not clean:
        raise typer.Exit(1)


@admin_app.command("retrain")
def retrain(submission_id: SubmissionId) -> None:
    """Train a scored or failed offline submission again, from scratch (every training seed of
    its phase), then evaluate it."""
    # deferred: CLI start-up time
    from server.services import admin

    ctx = _Context()
    attempt = _run(lambda: admin.retrain(ctx.db, ctx.settings.service, ctx.queue, submission_id))
    console.print(f"submission {submission_id}: training attempt {attempt} queued")


@admin_app.command("model")
def model(
    submission_id: SubmissionId,
    out: Annotated[
        Path | None, typer.Option(help="File to write (default: model-<sha>.tar.gz).")
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(help="Which training seed's model, when the phase trains several."),
    ] = None,
) -> None:
    """Download an offline submission's trained output for audit (checked against its sha256)."""
    # deferred: CLI start-up time
    import hashlib

    # deferred: CLI start-up time
    from server.services import admin

    ctx = _Context()
    trained = _run(lambda: admin.trained_model(ctx.db, submission_id, seed))
    path = ctx.store.fetch(trained.key, out or Path(trained.file_name))
    if hashlib.sha256(path.read_bytes()).hexdigest() != trained.sha256:
        raise _fail(ValueError(f"{path} does not match the stored sha256 {trained.sha256}"))
    console.print(
        f"wrote {path} ({trained.size} bytes, sha256 {trained.sha256}, training attempt "
        f"{trained.attempt}, seed {trained.seed})"
    )


@admin_app.command("status")
def status() -> None:
    """Queue depth, workers, submissions by status, runs whose lease expired, submissions
    waiting longer than ARENA_OVERDUE_AFTER_S, phases nothing can be evaluated in, and training
    seeds lost on our side (waiting for a requeue)."""
    # deferred: CLI start-up time
    from server.services import admin

    ctx = _Context()
    state = admin.service_status(ctx.db, ctx.settings, ctx.queue)
    depth = "broker unreachable" if state.queue_depth is None else state.queue_depth
    console.print(f"queue depth: {depth}")
    if state.workers is None:
        console.print("workers: (the embedded broker cannot list workers)")
    else:
        console.print(f"workers ({len(state.workers)}): {', '.join(state.workers) or 'none'}")
    console.print(f"running evaluations: {state.running_runs}")
    print_rows(
        console,
        ("submission status", "submissions"),
        list(state.submissions.items()),
        title="submissions by status",
        numeric=("submissions",),
    )
    if state.broken_phases:
        print_rows(
            console,
            ("phase", "cannot evaluate because"),
            list(state.broken_phases.items()),
            title="BROKEN PHASES: fix with `arena admin phases set`",
        )
    else:
        console.print("broken phases: none")
    if state.stuck_runs:
        print_rows(
            console,
            ("run", "submission", "worker", "lease expired at"),
            [
                (run.run_id, run.submission_id, run.worker, _at(run.lease_expires_at))
                for run in state.stuck_runs
            ],
            title="stuck runs",
            numeric=("run", "submission"),
        )
    else:
        console.print("stuck runs: none")
    limit = ctx.settings.service.overdue_after_s
    if state.overdue:
        print_rows(
            console,
            ("submission", "team", "phase", "status", "since"),
            [(o.submission_id, o.team, o.phase, o.status, _at(o.since)) for o in state.overdue],
            title=f"overdue (in the same state for more than {limit:.0f} s)",
            numeric=("submission",),
        )
    else:
        console.print(f"overdue (same state for more than {limit:.0f} s): none")
    if state.lost_seeds:
        print_rows(
            console,
            ("submission", "seed", "lost on our side"),
            [(lost.submission_id, lost.seed, lost.lost) for lost in state.lost_seeds],
            title="training seeds waiting: `arena admin submissions requeue ID` sends them again",
            numeric=("submission", "seed"),
        )


def _at(moment) -> str:
    return "-" if moment is None else f"{moment:%Y-%m-%d %H:%M:%S} UTC"


@leaderboard_app.command("export")
def leaderboard_export(
    track: Annotated[Track, typer.Option(help="Which track's leaderboard.")] = Track.freestyle,
    phase: Annotated[str, typer.Option(help="Which phase's leaderboard.")] = "final",
    out: Annotated[Path | None, typer.Option(help="File to write (default: stdout).")] = None,
    gap_from: Annotated[
        str | None,
        typer.Option(help="Add each entry's generalisation gap to this phase (e.g. validation)."),
    ] = None,
) -> None:
    """The leaderboard of one phase and track as CSV."""
    # deferred: CLI start-up time
    from server.services import leaderboard, phases

    ctx = _Context()
    with ctx.db.read_session() as session:
        _run(lambda: phases.get_phase(session, phase))
        board = leaderboard.compute(session, track, phase)
        if gap_from is not None:
            _run(lambda: phases.get_phase(session, gap_from))
            board = leaderboard.with_gap(board, leaderboard.compute(session, track, gap_from))
        text = leaderboard.to_csv(board)
    if out is None:
        typer.echo(text, nl=False)
        return
    try:
        out.write_text(text)
    except OSError as exc:
        raise _fail(ValueError(f"cannot write {out}: {exc.strerror or exc}")) from None
    console.print(f"wrote {out}")


# --- service ----------------------------------------------------------------------------------


@service_app.command("serve")
def serve(host: str = "127.0.0.1", port: int = 8000, workers: int = 1) -> None:
    """Run the API and web pages (uvicorn)."""
    # deferred: CLI start-up time
    from functools import partial

    import uvicorn

    from arena.config import get_settings
    from server.core.http import HeaderDeadlineProtocol

    service = get_settings().service
    uvicorn.run(
        "server.app:create_app",
        factory=True,
        host=host,
        port=port,
        workers=workers,
        # Slow clients hold no worker: headers have a deadline, idle keep-alives end.
        http=partial(HeaderDeadlineProtocol, header_timeout_s=service.http_header_timeout_s),
        timeout_keep_alive=service.http_keep_alive_s,
    )


@service_app.command("worker")
def worker(
    concurrency: Annotated[
        int | None, typer.Option(help="Scenarios at once (default: jobs).")
    ] = None,
    loglevel: str = "INFO",
) -> None:
    """Run a Celery worker that evaluates submissions."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from server.core.celery_app import create_celery_app

    app = create_celery_app(get_settings())
    argv = [
        "worker",
        f"--loglevel={loglevel}",
        "-O",
        "fair",
        "--without-mingle",
        "--without-gossip",
    ]
    if concurrency:
        argv.append(f"--concurrency={concurrency}")
    app.worker_main(argv)


@service_app.command("up")
def up(
    host: str = "127.0.0.1",
    port: int = 8000,
    demo_team: str = "demo",
) -> None:
    """Everything on this machine: database, scenario suites, API and a worker (Ctrl-C stops)."""
    # deferred: CLI start-up time
    from server.embedded import AlreadyServed, run_embedded

    try:
        run_embedded(console, host=host, port=port, demo_team=demo_team)
    except AlreadyServed as exc:
        raise _fail(exc) from None


# --- phases -----------------------------------------------------------------------------------


def _moment(text: str | None, option: str):
    # deferred: CLI start-up time
    from datetime import UTC, datetime

    if text is None:
        return None
    try:
        moment = datetime.fromisoformat(text)
    except ValueError:
        raise typer.BadParameter(
            f"{text!r} is not a date: use ISO 8601, e.g. 2026-12-01T00:00", param_hint=option
        ) from None
    return moment if moment.tzinfo else moment.replace(tzinfo=UTC)


@phases_app.command("list")
def phases_list() -> None:
    """Every phase: its suite, visibility, dates (UTC), daily quota, episodes per reactive
    scenario (what an evaluation costs) and whether it is open."""
    # deferred: CLI start-up time
    from server.models import utcnow
    from server.services import phases

    ctx = _Context()
    with ctx.db.read_session() as session:
        rows = phases.list_phases(session)
        broken = phases.misconfigured(session, ctx.settings)
    moment = utcnow()
    print_rows(
        console,
        (
            "phase",
            "suite",
            "visibility",
            "starts",
            "ends",
            "daily quota",
            "episodes",
            "cpu act/episode/evaluation [s]",
            "seeds",
            "open",
        ),
        [
            (
                phase.name,
                phase.suite,
                str(phase.visibility),
                f"{phase.starts_at:%Y-%m-%d %H:%M}" if phase.starts_at else "-",
                f"{phase.ends_at:%Y-%m-%d %H:%M}" if phase.ends_at else "-",
                phases.daily_quota(phase, ctx.settings.service),
                f"{phases.episodes_per_scenario(phase, ctx.settings.evaluation)}"
                + ("+" if phase.adaptive_target is not None else ""),
                _cpu_cell(phases.cpu_limits(phase, ctx.settings.sandbox)),
                phase.training_seeds,
                _open_cell(phase, moment, broken),
            )
            for phase in rows
        ],
        numeric=("daily quota", "episodes", "seeds"),
    )
    released = [phase.name for phase in rows if phase.released_at is not None]
    console.print(
        "episodes: of each reactive scenario, each with other traffic; an evaluation takes about "
        "that many times as long as with one",
        style="dim",
    )
    if released:
        console.print(f"released (suite downloadable, episodes visible): {', '.join(released)}")
    for name, why in broken.items():
        console.print(
            f"BROKEN {why}: uploads refused until `arena admin phases set {name} ...` fixes it",
            markup=False,
            highlight=False,
        )
    for phase in rows:
        adaptive = phases.adaptive_cost(phase, ctx.settings.evaluation)
        if adaptive is not None:
            console.print(f"{phase.name} (+): {adaptive}", markup=False)


def _open_cell(phase, moment, broken: dict[str, str]) -> str:
    # deferred: CLI start-up time
    from server.services import phases

    if phase.name in broken:  # uploads refused whatever its dates say
        return "no: broken"
    return "yes" if phases.is_open(phase, moment) else "no"


def _cpu_cell(limits) -> str:
    return f"{limits.step_s:g} / {limits.episode_s:g} / {limits.evaluation_s:g}"


@phases_app.command("release")
def phases_release(name: Annotated[str, typer.Argument(help="A phase that has closed.")]) -> None:
    """After a phase closes: make its suite downloadable and let every team watch its own
    episodes of it (refused while the phase is open)."""
    from server.services import release

    ctx = _Context()
    phase = _run(lambda: release.release_phase(ctx.db, name))
    console.print(
        f"phase [bold]{phase.name}[/bold] released at {phase.released_at:%Y-%m-%d %H:%M} UTC: "
        f"its suite is at /api/v1/scenarios/released/{phase.name}.zip and every team can watch "
        "its own episodes"
    )


SuiteOption = Annotated[str | None, typer.Option(help="`public`, `hidden` or a suite folder.")]
VisibilityOption = Annotated[
    str | None, typer.Option(help="`full` (validation) or `hidden` (final).")
]
StartsOption = Annotated[str | None, typer.Option(help="Opens at (ISO 8601, UTC).")]
EndsOption = Annotated[str | None, typer.Option(help="Closes at (ISO 8601, UTC).")]
QuotaOption = Annotated[int | None, typer.Option(help="Submissions per team, track and day.")]
ProfileOption = Annotated[str | None, typer.Option(help="Scoring profile of the phase.")]
EpisodesOption = Annotated[
    int | None,
    typer.Option(
        help="Episodes of each reactive scenario, each with other traffic; evaluation takes "
        "about this many times as long (default: ARENA_EPISODES_PER_SCENARIO)."
    ),
]
OpenEndedOption = Annotated[bool, typer.Option("--open-ended", help="No start and no end date.")]
AdaptiveTargetOption = Annotated[
    float | None,
    typer.Option(
        help="Adaptive evaluation: add rounds of --episodes episodes per reactive scenario "
        "while completion's 95% interval half-width is above this (with --max-episodes)."
    ),
]
MaxEpisodesOption = Annotated[
    int | None, typer.Option(help="Adaptive evaluation: the most episodes per scenario.")
]
StepCpuOption = Annotated[
    float | None,
    typer.Option(help="Agent CPU seconds one act may use (default: ARENA_STEP_CPU_S)."),
]
EpisodeCpuOption = Annotated[
    float | None,
    typer.Option(
        help="Agent CPU seconds of one episode's acts together (default: ARENA_EPISODE_CPU_S)."
    ),
]
EvaluationCpuOption = Annotated[
    float | None,
    typer.Option(
        help="Agent CPU seconds of one evaluation's episodes together; past it the rest are "
        "not run and the submission fails (default: ARENA_EVALUATION_CPU_S)."
    ),
]
TrainingSeedsOption = Annotated[
    int | None,
    typer.Option(
        help="Track 2: train each offline submission this many times (1 to 16), each with "
        "its own ARENA_TRAIN_SEED, and score it over them; training and evaluation take "
        "about this many times as long."
    ),
]
DryRunOption = Annotated[
    bool, typer.Option("--dry-run", help="Say what the phase would cost; save nothing.")
]


@phases_app.command("create")
def phases_create(
    name: Annotated[str, typer.Argument(help="The new phase's name.")],
    suite: Annotated[str, typer.Option(help="`public`, `hidden` or a suite folder.")],
    visibility: VisibilityOption = None,
    starts: StartsOption = None,
    ends: EndsOption = None,
    open_ended: Annotated[
        bool, typer.Option("--open-ended", help="Never closes (instead of --ends).")
    ] = False,
    quota: QuotaOption = None,
    profile: ProfileOption = None,
    episodes: EpisodesOption = None,
    adaptive_target: AdaptiveTargetOption = None,
    max_episodes: MaxEpisodesOption = None,
    step_cpu: StepCpuOption = None,
    episode_cpu: EpisodeCpuOption = None,
    evaluation_cpu: EvaluationCpuOption = None,
    training_seeds: TrainingSeedsOption = None,
    dry_run: DryRunOption = False,
) -> None:
    """Create a phase (refused if it exists: `phases set` changes one). It needs a suite and
    when it closes (--ends, or --open-ended); it opens at --starts, or now, on every team's
    submit form (hidden visibility unless --visibility full)."""
    # deferred: CLI start-up time
    from server.services import phases

    changes = _phase_changes(
        suite=suite,
        visibility=visibility,
        starts=starts,
        ends=ends,
        open_ended=open_ended,
        quota=quota,
        profile=profile,
        episodes=episodes,
        adaptive_target=adaptive_target,
        max_episodes=max_episodes,
        step_cpu=step_cpu,
        episode_cpu=episode_cpu,
        evaluation_cpu=evaluation_cpu,
        training_seeds=training_seeds,
    )
    ctx = _Context()
    phase = _run(lambda: phases.create_phase(ctx.db, ctx.settings, name, changes, dry_run=dry_run))
    _say_phase(ctx, phase, "not created (dry run)" if dry_run else "created")


@phases_app.command("set")
def phases_set(
    name: Annotated[str, typer.Argument(help="An existing phase (`phases create` makes one).")],
    suite: SuiteOption = None,
    visibility: VisibilityOption = None,
    starts: StartsOption = None,
    ends: EndsOption = None,
    quota: QuotaOption = None,
    profile: ProfileOption = None,
    episodes: EpisodesOption = None,
    open_ended: OpenEndedOption = False,
    adaptive_target: AdaptiveTargetOption = None,
    max_episodes: MaxEpisodesOption = None,
    fixed_episodes: Annotated[
        bool, typer.Option("--fixed-episodes", help="Turn adaptive evaluation off.")
    ] = False,
    step_cpu: StepCpuOption = None,
    episode_cpu: EpisodeCpuOption = None,
    evaluation_cpu: EvaluationCpuOption = None,
    default_cpu_limits: Annotated[
        bool,
        typer.Option(
            "--default-cpu-limits", help="Clear the phase's CPU limits: the settings' apply."
        ),
    ] = False,
    training_seeds: TrainingSeedsOption = None,
    dry_run: DryRunOption = False,
) -> None:
    """Change some settings of an existing phase; an unknown name is refused with the nearest
    known one (`phases create` makes a new phase)."""
    # deferred: CLI start-up time
    from server.services import phases

    changes = _phase_changes(
        suite=suite,
        visibility=visibility,
        starts=starts,
        ends=ends,
        open_ended=open_ended,
        quota=quota,
        profile=profile,
        episodes=episodes,
        adaptive_target=adaptive_target,
        max_episodes=max_episodes,
        step_cpu=step_cpu,
        episode_cpu=episode_cpu,
        evaluation_cpu=evaluation_cpu,
        training_seeds=training_seeds,
        fixed_episodes=fixed_episodes,
        default_cpu_limits=default_cpu_limits,
    )
    ctx = _Context()
    phase = _run(lambda: phases.set_phase(ctx.db, ctx.settings, name, changes, dry_run=dry_run))
    _say_phase(ctx, phase, "unchanged (dry run)" if dry_run else "saved")


def _phase_changes(
    *,
    suite: str | None,
    visibility: str | None,
    starts: str | None,
    ends: str | None,
    open_ended: bool,
    quota: int | None,
    profile: str | None,
    episodes: int | None,
    adaptive_target: float | None,
    max_episodes: int | None,
    step_cpu: float | None,
    episode_cpu: float | None,
    evaluation_cpu: float | None,
    training_seeds: int | None,
    fixed_episodes: bool = False,
    default_cpu_limits: bool = False,
):
    # deferred: CLI start-up time
    from server.models import Visibility
    from server.services import phases

    if visibility is not None and visibility not in set(Visibility):
        raise typer.BadParameter("use `full` or `hidden`", param_hint="--visibility")
    return phases.PhaseChanges(
        suite=suite,
        visibility=Visibility(visibility) if visibility else None,
        starts_at=_moment(starts, "--starts"),
        ends_at=_moment(ends, "--ends"),
        daily_quota=quota,
        scoring_profile=profile,
        episodes_per_scenario=episodes,
        clear_dates=open_ended,
        adaptive_target=adaptive_target,
        max_episodes=max_episodes,
        fixed_episodes=fixed_episodes,
        step_cpu_s=step_cpu,
        episode_cpu_s=episode_cpu,
        evaluation_cpu_s=evaluation_cpu,
        default_cpu_limits=default_cpu_limits,
        training_seeds=training_seeds,
    )


def _say_phase(ctx: _Context, phase, outcome: str) -> None:
    """The phase just created or changed, with what an evaluation in it costs."""
    from server.services import phases

    console.print(f"phase [bold]{phase.name}[/bold] {outcome}")
    per_scenario = phases.episodes_per_scenario(phase, ctx.settings.evaluation)
    adaptive = phases.adaptive_cost(phase, ctx.settings.evaluation)
    if adaptive is not None:
        console.print(adaptive, markup=False)
    elif per_scenario > 1:
        console.print(phases.episodes_cost(per_scenario))
    console.print(
        phases.describe_cpu_limits(phases.cpu_limits(phase, ctx.settings.sandbox)), markup=False
    )
    if phase.training_seeds > 1:
        console.print(phases.seeds_cost(phase.training_seeds), markup=False)


@phases_app.command("delete")
def phases_delete(
    name: Annotated[str, typer.Argument(help="The phase.")],
    yes: Annotated[bool, typer.Option("--yes", help="Do not ask for confirmation.")] = False,
) -> None:
    """Delete a phase and every submission made in it (uploads, results, scores, records)."""
    from server.services import removal

    ctx = _Context()
    with ctx.db.read_session() as session:
        preview = _run(lambda: removal.phase_removal(session, name))
    _confirm(preview, yes)
    done = _run(lambda: removal.remove_phase(ctx.db, ctx.store, name))
    console.print(f"deleted {done.describe()}", markup=False, highlight=False)


@teams_app.command("delete")
def teams_delete(
    name: Annotated[str, typer.Argument(help="The team.")],
    yes: Annotated[bool, typer.Option("--yes", help="Do not ask for confirmation.")] = False,
) -> None:
    """Delete a team, its tokens and every submission it made (uploads, results, scores,
    records, trained models)."""
    from server.services import removal

    ctx = _Context()
    with ctx.db.read_session() as session:
        preview = _run(lambda: removal.team_removal(session, name))
    _confirm(preview, yes)
    done = _run(lambda: removal.remove_team(ctx.db, ctx.store, name))
    console.print(f"deleted {done.describe()}", markup=False, highlight=False)


def _confirm(preview, yes: bool) -> None:
    console.print(f"this deletes {preview.describe()}", markup=False, highlight=False)
    if not yes and not typer.confirm("delete for good?", default=False):
        console.print("nothing deleted")
        raise typer.Exit(1)
