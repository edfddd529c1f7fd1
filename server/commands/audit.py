"""`arena admin audit`: re-run scored submissions from their manifests and compare record by
record (`server/services/audit.py`)."""

from __future__ import annotations

from typing import Annotated

import typer

from server.commands.console import console, err_console, fail, progress
from server.commands.context import AdminContext, OptionalSubmissionId, or_fail

app = typer.Typer(no_args_is_help=True)


@app.command("audit")
def audit(
    submission_id: OptionalSubmissionId = None,
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
    # deferred: CLI start-up time
    from server.services import audit as audits

    if (submission_id is None) == (sample is None):
        raise typer.BadParameter("give one submission id or --sample N")
    ctx = AdminContext()
    targets = [submission_id] if sample is None else audits.sample(ctx.db, sample)
    if not targets:
        raise fail(ValueError("no leaderboard entry to audit"))
    clean = True
    err_console.print(
        f"auditing {len(targets)} submission(s): {', '.join(map(str, targets))}",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )
    for target in targets:
        with progress(f"submission {target}", "episodes re-run") as step:
            report = or_fail(
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
