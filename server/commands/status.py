"""`arena admin status`: how the service is doing (`server/services/admin.py: service_status`)."""

from __future__ import annotations

import typer
from rich.markup import escape

from arena.terminal import print_rows
from server.commands.console import console, moment_text
from server.commands.context import AdminContext

app = typer.Typer(no_args_is_help=True)


@app.command("status")
def status() -> None:
    """Queue depth, workers, the simulator's per-step core (compiled, or the pure-Python
    reference and why) here and in each worker, submissions by status, runs whose lease expired,
    submissions waiting longer than ARENA_OVERDUE_AFTER_S, phases nothing can be evaluated in,
    and training seeds lost on our side (waiting for a requeue)."""
    # deferred: CLI start-up time
    from server.services import admin

    ctx = AdminContext()
    state = admin.service_status(ctx.db, ctx.settings, ctx.queue)
    depth = "broker unreachable" if state.queue_depth is None else state.queue_depth
    console.print(f"queue depth: {depth}")
    if state.workers is None:
        console.print("workers: (the embedded broker cannot list workers)")
    else:
        console.print(f"workers ({len(state.workers)}): {', '.join(state.workers) or 'none'}")
    _print_cores(state.simulator_core, state.worker_cores)
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
                (run.run_id, run.submission_id, run.worker, moment_text(run.lease_expires_at))
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
            [
                (o.submission_id, o.team, o.phase, o.status, moment_text(o.since))
                for o in state.overdue
            ],
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


def _print_cores(here: str, workers: dict[str, str] | None) -> None:
    """The core of this installation (the embedded worker of `arena up` runs it) and of each
    worker that answered, grouped by core; a pure-Python one stands out: it is several times
    slower per step."""

    def shown(core: str) -> str:
        return escape(core) if core == "compiled" else f"[bold yellow]{escape(core)}[/]"

    console.print(f"simulator core here: {shown(here)}")
    if workers:
        by_core: dict[str, list[str]] = {}
        for name, core in sorted(workers.items()):
            by_core.setdefault(core, []).append(name)
        listed = "; ".join(
            f"{shown(core)} ({escape(', '.join(names))})" for core, names in by_core.items()
        )
        console.print(f"simulator core of the workers: {listed}")
