"""`arena admin phases ...`: competition phases, their suites, dates, quotas and what an
evaluation in them costs (`server/services/phases.py`; releasing one, `server/services/release.py`;
deleting one, `server/services/removal.py`)."""

from __future__ import annotations

from typing import Annotated

import typer

from arena.terminal import print_rows
from server.commands.console import console
from server.commands.context import AdminContext, or_fail
from server.commands.phase_options import (
    AdaptiveTargetOption,
    DryRunOption,
    EndsOption,
    EpisodeCpuOption,
    EpisodesOption,
    EvaluationCpuOption,
    MaxEpisodesOption,
    OpenEndedOption,
    ProfileOption,
    QuotaOption,
    StartsOption,
    StepCpuOption,
    SuiteOption,
    TrainingSeedsOption,
    VisibilityOption,
    phase_changes,
)
from server.commands.removal import delete_after_asking

app = typer.Typer(no_args_is_help=True)


@app.command("list")
def phases_list() -> None:
    """Every phase: its suite, visibility, dates (UTC), daily quota, episodes per reactive
    scenario (what an evaluation costs) and whether it is open."""
    # deferred: CLI start-up time
    from server.models import utcnow
    from server.services import phases

    ctx = AdminContext()
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


@app.command("release")
def phases_release(name: Annotated[str, typer.Argument(help="A phase that has closed.")]) -> None:
    """After a phase closes: make its suite downloadable and let every team watch its own
    episodes of it (refused while the phase is open)."""
    from server.services import release

    ctx = AdminContext()
    phase = or_fail(lambda: release.release_phase(ctx.db, name))
    console.print(
        f"phase [bold]{phase.name}[/bold] released at {phase.released_at:%Y-%m-%d %H:%M} UTC: "
        f"its suite is at /api/v1/scenarios/released/{phase.name}.zip and every team can watch "
        "its own episodes"
    )


@app.command("create")
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

    changes = phase_changes(
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
    ctx = AdminContext()
    phase = or_fail(
        lambda: phases.create_phase(ctx.db, ctx.settings, name, changes, dry_run=dry_run)
    )
    _say_phase(ctx, phase, "not created (dry run)" if dry_run else "created")


@app.command("set")
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

    changes = phase_changes(
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
    ctx = AdminContext()
    phase = or_fail(lambda: phases.set_phase(ctx.db, ctx.settings, name, changes, dry_run=dry_run))
    _say_phase(ctx, phase, "unchanged (dry run)" if dry_run else "saved")


def _say_phase(ctx: AdminContext, phase, outcome: str) -> None:
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


@app.command("delete")
def phases_delete(
    name: Annotated[str, typer.Argument(help="The phase.")],
    yes: Annotated[bool, typer.Option("--yes", help="Do not ask for confirmation.")] = False,
) -> None:
    """Delete a phase and every submission made in it (uploads, results, scores, records)."""
    # deferred: CLI start-up time
    from server.services import removal

    delete_after_asking(name, yes, removal.phase_removal, removal.remove_phase)
