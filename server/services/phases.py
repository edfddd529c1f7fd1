"""Competition phases: which suite a submission is evaluated on, when uploads are open, the daily
quota, and what its team may see."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from arena.config import (
    EvaluationSettings,
    SandboxSettings,
    ServiceSettings,
    Settings,
    SuiteSettings,
)
from arena.cpu_limits import CpuLimits
from arena.errors import ArenaError, SuiteError
from arena.names import did_you_mean
from arena.suite import Suite, load_suite, resolve_suite
from evaluator.scoring import ProfileError, ScoringProfile, load_profile
from server.core.db import Database
from server.models import Phase, Visibility, utcnow
from server.services.errors import Conflict, Forbidden, InvalidInput, NotFound

DEFAULT_PHASE = "final"
# Episodes of each reactive scenario a phase may ask for, fixed or adaptive: each multiplies an
# evaluation's cost.
MAX_EPISODES_PER_SCENARIO = 64
# Trainings per offline submission (each a whole training run): at most this many.
MAX_TRAINING_SEEDS = 16


def get_phase(session: Session, name: str) -> Phase:
    phase = session.scalar(select(Phase).where(Phase.name == name))
    if phase is None:
        raise NotFound(_unknown_phase(session, name))
    return phase


def _unknown_phase(session: Session, name: str) -> str:
    """Why ``name`` is no phase: the nearest known name first (a typo), then all of them."""
    known = [phase.name for phase in list_phases(session)]
    return f"no phase {name!r}{did_you_mean(name, known)} (phases: {', '.join(known) or 'none'})"


def list_phases(session: Session) -> list[Phase]:
    return list(session.scalars(select(Phase).order_by(Phase.id)))


def is_open(phase: Phase, moment: datetime) -> bool:
    started = phase.starts_at is None or phase.starts_at <= moment
    return started and (phase.ends_at is None or moment < phase.ends_at)


def open_phases(session: Session, moment: datetime | None = None) -> list[Phase]:
    moment = moment or utcnow()
    return [phase for phase in list_phases(session) if is_open(phase, moment)]


def check_open(phase: Phase, moment: datetime) -> None:
    """Refuse an upload outside the phase's dates, saying when it opens or that it closed."""
    if phase.starts_at is not None and moment < phase.starts_at:
        raise Forbidden(f"phase {phase.name!r} opens for submissions at {_when(phase.starts_at)}")
    if phase.ends_at is not None and moment >= phase.ends_at:
        raise Forbidden(f"phase {phase.name!r} closed for submissions at {_when(phase.ends_at)}")


def _when(moment: datetime) -> str:
    return moment.strftime("%Y-%m-%d %H:%M UTC")


def daily_quota(phase: Phase, service: ServiceSettings) -> int:
    return phase.daily_quota if phase.daily_quota is not None else service.daily_quota


def suite_dir(phase: Phase, suites: SuiteSettings, data_dir: Path) -> Path:
    return resolve_suite(phase.suite, suites, data_dir)


def scoring_profile(phase: Phase, evaluation: EvaluationSettings) -> str:
    return phase.scoring_profile or evaluation.scoring_profile


def episodes_per_scenario(phase: Phase, evaluation: EvaluationSettings) -> int:
    if phase.episodes_per_scenario is not None:
        return phase.episodes_per_scenario
    return evaluation.episodes_per_scenario


def cpu_limits(phase: Phase, sandbox: SandboxSettings) -> CpuLimits:
    """The agent's CPU limits in the phase: its overrides, else the sandbox settings'."""
    return sandbox.cpu_limits.overridden(
        phase.step_cpu_s, phase.episode_cpu_s, phase.evaluation_cpu_s
    )


def describe_cpu_limits(limits: CpuLimits) -> str:
    """The limits as said wherever a phase is shown or set."""
    return (
        f"agent CPU: {limits.step_s:g} s per act, {limits.episode_s:g} s per episode, "
        f"{limits.evaluation_s:g} s per evaluation"
    )


def episodes_cost(per_scenario: int) -> str:
    """The cost of several episodes, said wherever the count is set or shown."""
    return (
        f"{per_scenario} episodes per reactive scenario: evaluation takes about {per_scenario} "
        "times as long"
    )


def seeds_cost(seeds: int) -> str:
    """The cost of several training seeds, said wherever the count is set or shown."""
    return (
        f"offline submissions train {seeds} times (seeds 0 to {seeds - 1}), each model "
        f"evaluated, and are scored over them: about {seeds} times as long"
    )


class PhaseMisconfigured(Conflict):
    """A phase whose suite or scoring profile cannot be used: nothing can be evaluated in it
    until an organiser fixes it (``arena admin phases set``)."""


@dataclass(frozen=True)
class PhaseSetup:
    """What an evaluation in a phase runs on, every part checked to load."""

    suite: Suite
    profile: ScoringProfile
    episodes_per_scenario: int


def phase_setup(phase: Phase, settings: Settings) -> PhaseSetup:
    """The phase's suite, profile and episode count, loaded; :class:`PhaseMisconfigured` (saying
    which part and why) if one of them cannot be used. (The whole settings: the suites, the
    data folder and the evaluation defaults.)"""
    data_dir = settings.storage.resolved_data_dir
    try:
        suite = load_suite(suite_dir(phase, settings.suites, data_dir))
    except SuiteError as exc:
        raise PhaseMisconfigured(f"phase {phase.name!r}: suite {phase.suite!r}: {exc}") from None
    if not suite.scenarios:
        raise PhaseMisconfigured(f"phase {phase.name!r}: suite {phase.suite!r} has no scenarios")
    try:
        profile = load_profile(scoring_profile(phase, settings.evaluation))
    except ProfileError as exc:
        raise PhaseMisconfigured(f"phase {phase.name!r}: {exc}") from None
    return PhaseSetup(suite, profile, episodes_per_scenario(phase, settings.evaluation))


def misconfigured(session: Session, settings: Settings) -> dict[str, str]:
    """Every phase that cannot start an evaluation, with why (``arena admin status``)."""
    problems = {}
    for phase in list_phases(session):
        try:
            phase_setup(phase, settings)
        except PhaseMisconfigured as exc:
            problems[phase.name] = exc.message
    return problems


def state(phase: Phase, moment: datetime) -> str:
    if phase.starts_at is not None and moment < phase.starts_at:
        return "not yet open"
    return "open" if is_open(phase, moment) else "closed"


def what_is_hidden(phase: Phase) -> str:
    """Said up front on a hidden phase's pages: what the team does not see, and why."""
    if team_sees_everything(phase):
        return ""
    return (
        f"The {phase.name} phase runs on a secret scenario suite: you see the four metrics, "
        "their interval, per-family figures and failure counts. Scenario ids, per-scenario "
        "results, replays and everything your agent printed go to the organisers only, so "
        "that the ranking measures how an agent drives in scenarios it has never seen, not "
        "how well it was tuned to them. Evaluate on the public scenarios (the validation "
        "phase, or `arena evaluate` locally) to see everything."
    )


def adaptive_cost(phase: Phase, evaluation: EvaluationSettings) -> str | None:
    """What an adaptive phase's evaluation costs (None for a fixed count), said before it is
    chosen and wherever it is shown."""
    if phase.adaptive_target is None or phase.max_episodes is None:
        return None
    first = episodes_per_scenario(phase, evaluation)
    return (
        f"adaptive: {first} episode(s) per reactive scenario, then {first} more per round while "
        f"completion's 95% interval is wider than +/-{phase.adaptive_target:g}, up to "
        f"{phase.max_episodes}: evaluation takes {first} to {phase.max_episodes} times as long "
        "as with one episode each"
    )


def team_sees_everything(phase: Phase) -> bool:
    """A phase of full visibility, or one the organisers released after it closed."""
    return phase.visibility is Visibility.full or phase.released_at is not None


def check_team_may_see_output(phase: Phase) -> None:
    if not team_sees_everything(phase):
        raise Forbidden(
            f"in the {phase.name!r} phase the agent's output and per-scenario results go to the "
            "organisers only; evaluate in the validation phase (or locally) to see them"
        )


@dataclass(frozen=True)
class PhaseChanges:
    suite: str | None = None
    visibility: Visibility | None = None
    starts_at: datetime | None = None
    ends_at: datetime | None = None
    daily_quota: int | None = None
    scoring_profile: str | None = None
    episodes_per_scenario: int | None = None
    clear_dates: bool = False  # open-ended again: no start and no end
    # Adaptive evaluation: both together; fixed_episodes turns it off again.
    adaptive_target: float | None = None
    max_episodes: int | None = None
    fixed_episodes: bool = False
    # The agent's CPU limits [s]; default_cpu_limits clears the phase's overrides (the
    # settings' apply again) before any given here.
    step_cpu_s: float | None = None
    episode_cpu_s: float | None = None
    evaluation_cpu_s: float | None = None
    default_cpu_limits: bool = False
    training_seeds: int | None = None  # Track 2: trainings of each offline submission


class _DryRun(ArenaError):
    """Carries a phase changed in a transaction that is then rolled back."""

    def __init__(self, phase: Phase) -> None:
        super().__init__("dry run")
        self.phase = phase


def create_phase(
    db: Database, settings: Settings, name: str, changes: PhaseChanges, *, dry_run: bool = False
) -> Phase:
    """Create the phase ``name``: refused if it exists (:func:`set_phase` changes one), without a
    suite, or without saying when it closes (an end date, or ``clear_dates`` for a phase that
    never does), so that no phase opens on every team's submit form by accident. Checked whole
    like :func:`set_phase`; ``dry_run``: nothing saved."""
    if changes.suite is None:
        raise InvalidInput(f"a new phase {name!r} needs --suite (public, hidden or DIR)")
    if changes.ends_at is None and not changes.clear_dates:
        raise InvalidInput(
            f"say when phase {name!r} closes: --ends T, or --open-ended for a phase that never does"
        )
    return _saved(db, settings, name, changes, dry_run, create=True)


def set_phase(
    db: Database, settings: Settings, name: str, changes: PhaseChanges, *, dry_run: bool = False
) -> Phase:
    """Change the given fields of the existing phase ``name`` (an unknown name is refused with
    the nearest known one: a typo never creates a phase; :func:`create_phase` does). The phase
    as it would be after the change is checked whole (suite loads, profile exists, dates
    ordered, counts in range) before anything is saved: a phase nothing can be evaluated in is
    never stored. ``dry_run``: the phase as it would be (to say what it would cost), nothing
    saved."""
    return _saved(db, settings, name, changes, dry_run, create=False)


def _saved(
    db: Database,
    settings: Settings,
    name: str,
    changes: PhaseChanges,
    dry_run: bool,
    *,
    create: bool,
) -> Phase:
    _check_changes(changes)
    try:
        with db.session() as session:
            phase = session.scalar(select(Phase).where(Phase.name == name).with_for_update())
            if create and phase is not None:
                raise Conflict(
                    f"phase {name!r} exists: change it with `arena admin phases set {name} ...`"
                )
            if not create and phase is None:
                raise NotFound(
                    f"{_unknown_phase(session, name)}; a new phase is made with "
                    f"`arena admin phases create {name} --suite S --ends T`"
                )
            if phase is None:
                phase = Phase(name=name, suite=changes.suite, visibility=Visibility.hidden)
                session.add(phase)
            _apply(phase, changes, settings)
            session.flush()
            session.expunge(phase)
            if dry_run:
                raise _DryRun(phase)  # rolls the transaction back
            return phase
    except _DryRun as done:
        return done.phase


def _check_changes(changes: PhaseChanges) -> None:
    """The changes that are wrong whatever the phase they are made to."""
    if changes.daily_quota is not None and changes.daily_quota < 0:
        raise InvalidInput("daily quota: a number of submissions, 0 or more")
    if changes.episodes_per_scenario is not None and not (
        1 <= changes.episodes_per_scenario <= MAX_EPISODES_PER_SCENARIO
    ):
        raise InvalidInput(
            f"episodes: how often each reactive scenario runs, 1 to {MAX_EPISODES_PER_SCENARIO}"
        )
    if changes.training_seeds is not None and not (
        1 <= changes.training_seeds <= MAX_TRAINING_SEEDS
    ):
        raise InvalidInput(
            f"training seeds: trainings of each offline submission, 1 to {MAX_TRAINING_SEEDS}"
        )
    if (changes.adaptive_target is None) != (changes.max_episodes is None):
        raise InvalidInput("adaptive evaluation needs both a target half-width and a cap")
    if changes.adaptive_target is not None and not 0 < changes.adaptive_target < 1:
        raise InvalidInput("adaptive target: completion's interval half-width, between 0 and 1")
    if changes.max_episodes is not None and not (
        1 <= changes.max_episodes <= MAX_EPISODES_PER_SCENARIO
    ):
        raise InvalidInput(f"max episodes: per reactive scenario, 1 to {MAX_EPISODES_PER_SCENARIO}")
    for field, value in _cpu_changes(changes).items():
        if value is not None and not value > 0:
            raise InvalidInput(f"{field}: CPU seconds, more than 0")
    if changes.scoring_profile is not None:
        try:
            load_profile(changes.scoring_profile)
        except ProfileError as exc:
            raise InvalidInput(str(exc)) from exc


def _apply(phase: Phase, changes: PhaseChanges, settings: Settings) -> None:
    """Make the changes to ``phase`` and check the result whole (refused: nothing saved)."""
    if changes.clear_dates:
        phase.starts_at = phase.ends_at = None
    for field in (
        "suite",
        "visibility",
        "starts_at",
        "ends_at",
        "daily_quota",
        "episodes_per_scenario",
        "training_seeds",
    ):
        value = getattr(changes, field)
        if value is not None:
            setattr(phase, field, value)
    if changes.scoring_profile is not None:
        phase.scoring_profile = changes.scoring_profile
    if changes.fixed_episodes:
        phase.adaptive_target = phase.max_episodes = None
    if changes.adaptive_target is not None:
        phase.adaptive_target = changes.adaptive_target
        phase.max_episodes = changes.max_episodes
    if changes.default_cpu_limits:
        phase.step_cpu_s = phase.episode_cpu_s = phase.evaluation_cpu_s = None
    for field, value in _cpu_changes(changes).items():
        if value is not None:
            setattr(phase, field, value)
    limits = cpu_limits(phase, settings.sandbox)
    if not limits.step_s <= limits.episode_s <= limits.evaluation_s:
        raise InvalidInput(
            f"the CPU limits must grow: an act's ({limits.step_s:g} s) at most an "
            f"episode's ({limits.episode_s:g} s), at most an evaluation's "
            f"({limits.evaluation_s:g} s)"
        )
    first = phase.episodes_per_scenario
    if phase.max_episodes is not None and first is not None and phase.max_episodes < first:
        raise InvalidInput("max episodes must be at least the episodes of the first round")
    if phase.starts_at and phase.ends_at and phase.ends_at <= phase.starts_at:
        raise InvalidInput("the phase must end after it starts")
    try:
        phase_setup(phase, settings)
    except PhaseMisconfigured as exc:
        raise InvalidInput(f"{exc.message}; nothing saved") from None


def _cpu_changes(changes: PhaseChanges) -> dict[str, float | None]:
    return {
        "step_cpu_s": changes.step_cpu_s,
        "episode_cpu_s": changes.episode_cpu_s,
        "evaluation_cpu_s": changes.evaluation_cpu_s,
    }
