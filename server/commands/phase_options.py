"""The options `arena admin phases create` and `phases set` share, and the
`server.services.phases.PhaseChanges` they make (dates parsed, visibility checked)."""

from __future__ import annotations

from typing import Annotated

import typer

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


def phase_changes(
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
