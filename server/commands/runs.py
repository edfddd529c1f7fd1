"""`arena admin rescore|rerun|retrain|compare|model`: what organisers do with a submission's
evaluation and training runs: score them again, run or train them again, compare two, fetch a
trained model (`server/services/admin.py`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from arena.figures import METRICS, metric_text
from arena.terminal import print_rows
from server.commands.console import console, fail, progress
from server.commands.context import AdminContext, OptionalSubmissionId, SubmissionId, or_fail

app = typer.Typer(no_args_is_help=True)


@app.command("rescore")
def rescore(
    submission_id: OptionalSubmissionId = None,
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
    from server.services import admin

    if sum((submission_id is not None, all_, phase is not None)) != 1:
        raise typer.BadParameter("give one of: a submission id, --phase NAME, --all")
    ctx = AdminContext()
    targets = or_fail(
        lambda: admin.rescore_targets(
            ctx.db, ctx.settings, submission_id=submission_id, phase=phase, profile=profile
        )
    )
    if not targets:
        raise fail(ValueError("no scored evaluation to re-score"))
    if profile is not None:
        console.print(f"phase [bold]{phase}[/bold] is now scored with profile {profile}")
    rows = []
    with progress("re-scoring", "runs") as step:
        for done, target in enumerate(targets, start=1):
            used, metrics = or_fail(
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
            step(done, len(targets))
    print_rows(
        console,
        ("submission", "attempt", "phase", "profile", "completion", "time", "humanness", "rules"),
        rows,
        numeric=("submission", "attempt", "completion", "time", "humanness", "rules"),
    )


@app.command("compare")
def compare(
    a: SubmissionId,
    b: SubmissionId,
    as_json: Annotated[bool, typer.Option("--json", help="The comparison as JSON.")] = False,
) -> None:
    """Two submissions side by side (hidden phases included): metrics with B - A and whether the
    completion intervals overlap, per family, and the episodes that ended differently."""
    # deferred: CLI start-up time
    from evaluator.compare import print_comparison
    from server.services import admin

    ctx = AdminContext()
    sides = [or_fail(lambda sid=sid: admin.comparison_side(ctx.db, sid)) for sid in (a, b)]
    print_comparison(console, *sides, as_json=as_json)


@app.command("rerun")
def rerun(submission_id: SubmissionId) -> None:
    """Simulate a scored or failed submission again, as a new attempt (an offline one: every
    seed's trained model)."""
    # deferred: CLI start-up time
    from server.services import admin

    ctx = AdminContext()
    attempt = or_fail(lambda: admin.rerun(ctx.db, ctx.settings, ctx.queue, submission_id))
    console.print(f"submission {submission_id}: attempt {attempt} queued")


@app.command("retrain")
def retrain(submission_id: SubmissionId) -> None:
    """Train a scored or failed offline submission again, from scratch (every training seed of
    its phase), then evaluate it."""
    # deferred: CLI start-up time
    from server.services import admin

    ctx = AdminContext()
    attempt = or_fail(lambda: admin.retrain(ctx.db, ctx.settings.service, ctx.queue, submission_id))
    console.print(f"submission {submission_id}: training attempt {attempt} queued")


@app.command("model")
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

    ctx = AdminContext()
    trained = or_fail(lambda: admin.trained_model(ctx.db, submission_id, seed))
    path = ctx.store.fetch(trained.key, out or Path(trained.file_name))
    if hashlib.sha256(path.read_bytes()).hexdigest() != trained.sha256:
        raise fail(ValueError(f"{path} does not match the stored sha256 {trained.sha256}"))
    console.print(
        f"wrote {path} ({trained.size} bytes, sha256 {trained.sha256}, training attempt "
        f"{trained.attempt}, seed {trained.seed})"
    )
