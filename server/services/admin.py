"""Organiser actions that re-drive evaluations: re-queue, re-run, re-train, re-score, the
trained model for audit, service status."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy import func, select

from arena.config import EvaluationSettings, ServiceSettings, Settings
from arena.episodes import Episode
from arena.outcome import FINISHED, ScenarioStatus
from evaluator.compare import METRIC_NAMES, SeedRun, Side, outcome_text
from evaluator.scoring import Interval, MetricSamples, ProfileError, ScoringProfile, load_profile
from evaluator.scoring import Metrics as ScoringMetrics
from evaluator.scoring.seeds import Spread
from server.core.artifacts import ArtifactStore
from server.core.db import Database
from server.core.queue import BROKER_ERRORS, TaskQueue
from server.jobs import leases
from server.models import EvaluationRun, SeedSetScore, Submission, utcnow
from server.services import (
    evaluation,
    phases,
    scoring,
    seed_sets,
    submissions,
    training,
)
from server.services.errors import Conflict, InvalidInput, NotFound
from server.services.evaluation import RunPlan, lock
from server.status import (
    ACTIVE_RUN,
    ACTIVE_SUBMISSION,
    ACTIVE_TRAINING,
    SUBMISSION_MOVES,
    RunStatus,
    SubmissionStatus,
    advance,
)
from sim.compiled import core_status


def requeue(db: Database, settings: Settings, queue: TaskQueue, submission_id: int) -> str:
    """Send an unfinished submission's lost work again (after lost messages or a dead worker).

    Only work nobody is doing: an evaluation whose lease a worker keeps renewing is healthy and
    is refused (re-sending it would only pile duplicates on the queue); of a stalled one, only
    the episodes neither finished nor held by a live claim go out again. Safe to repeat: tasks
    skip what is already done."""
    with db.session() as session:
        submission = lock(session, Submission, submission_id)
        validating = submission.status == SubmissionStatus.validating
    if validating:
        # A validation held by a live worker ignores the re-sent task (its lease fences it).
        queue.validate(submission_id)
        return "validation re-sent"
    with db.session() as session:
        submission = lock(session, Submission, submission_id)
        plan = None
        if submission.status == SubmissionStatus.received:
            submission.status = advance(
                submission.status, SubmissionStatus.queued, SUBMISSION_MOVES
            )
        # A training still held by a live worker ignores the re-sent task; a dead worker's is
        # handed out by the reaper once its lease expires. Every seed's work goes again, and a
        # seed lost on our side trains again (a new job of the same set).
        training_ids = [job.id for job in submission.trainings if job.status in ACTIVE_TRAINING]
        replaced = training.replace_lost_seeds(session, settings.service, submission)
        training_ids += [job.id for job in replaced]
        replaced_seeds = [job.seed for job in replaced]
        plans: list[RunPlan] = []
        # A seed whose evaluation was lost on our side is evaluated again (a new run).
        lost_runs = evaluation.rerun_lost_seeds(session, settings, submission)
        rerun_seeds = [session.get(EvaluationRun, p.run_id).training.seed for p in lost_runs]
        if submission.status == SubmissionStatus.queued:
            submission.queued_at = utcnow()
        else:
            runs = [
                run
                for run in submission.runs
                if run.status in ACTIVE_RUN and run.id not in {p.run_id for p in lost_runs}
            ]
            if not runs and not training_ids and not lost_runs:
                raise Conflict(
                    f"submission {submission_id} is {submission.status} with no evaluation in "
                    "progress; use rerun for a new attempt"
                )
            alive: list[Conflict] = []
            for run in runs:
                try:
                    plans.append(_lost_work(settings.service, run, submission_id))
                except Conflict as exc:
                    alive.append(exc)
            if alive and not plans and not training_ids and not lost_runs:
                raise alive[0]
    for training_id in training_ids:
        queue.train(training_id)
    for plan in (*plans, *lost_runs):
        queue.send(plan)
    said = []
    if training_ids:
        count = len(training_ids)
        said.append("training re-sent" if count == 1 else f"{count} trainings re-sent")
    if replaced_seeds:
        seeds = ", ".join(map(str, replaced_seeds))
        said.append(f"seed(s) {seeds} lost on our side: trained again")
    if rerun_seeds:
        seeds = ", ".join(map(str, rerun_seeds))
        said.append(f"seed(s) {seeds} lost on our side: evaluated again")
    if plans:
        episodes = sum(len(plan.episodes) for plan in plans)
        said.append(
            f"{episodes} episode(s) re-sent (neither finished nor held by a worker)"
            if episodes
            else "aggregation re-sent"
        )
    if said:
        return "; ".join(said)
    queue.evaluate(submission_id)
    return "evaluation queued"


def _lost_work(service: ServiceSettings, run: EvaluationRun, submission_id: int) -> RunPlan:
    moment = utcnow()
    if run.lease_expires_at is not None and run.lease_expires_at > moment:
        done = sum(r.status in FINISHED for r in run.results)
        raise Conflict(
            f"submission {submission_id}: its evaluation (run {run.id}, {run.status}, "
            f"{done}/{run.episode_count} episodes done) is alive: a worker renewed it within "
            f"the last {service.lease_seconds} s, so nothing is lost and nothing is "
            "re-sent. "
            "Work a dead worker held is re-sent by the reaper; requeue again if its lease runs "
            "out and it still does not move"
        )
    held = set()
    for result in run.results:
        if result.status != ScenarioStatus.running:
            continue
        if result.worker and result.lease_expires_at and result.lease_expires_at > moment:
            held.add(Episode(result.scenario_id, result.episode))
        else:  # a dead worker's claim: released, so the re-sent task can take it
            result.worker, result.lease_expires_at = "", None
    pending = tuple(e for e in evaluation.pending_episodes(run) if e not in held)
    run.lease_expires_at = leases.lease_until(service)
    return RunPlan(run_id=run.id, episodes=pending, aggregate=not pending and not held)


def rerun(db: Database, settings: Settings, queue: TaskQueue, submission_id: int) -> int:
    """A new simulation attempt (a run per seed of an offline submission's seed set); returns
    the attempt number of its first run."""
    with db.session() as session:
        plans = evaluation.rerun(session, settings, submission_id)
        attempt = session.get(EvaluationRun, plans[0].run_id).attempt
    for plan in plans:
        queue.send(plan)
    return attempt


def retrain(db: Database, service: ServiceSettings, queue: TaskQueue, submission_id: int) -> int:
    """A new training attempt of an offline submission, from scratch, every seed of its phase
    (then their evaluations); returns the attempt number of its first seed's job."""
    with db.session() as session:
        jobs = training.retrain(session, service, submission_id)
        training_ids, attempt = [job.id for job in jobs], jobs[0].attempt
    for training_id in training_ids:
        queue.train(training_id)
    return attempt


@dataclass(frozen=True)
class TrainedModel:
    """The stored trained output of one of a submission's trainings."""

    key: str
    sha256: str
    size: int  # [bytes]
    attempt: int
    seed: int

    @property
    def file_name(self) -> str:
        return f"model-{self.sha256[:12]}.tar.gz"


def trained_model(db: Database, submission_id: int, seed: int | None = None) -> TrainedModel:
    """The latest trained output, or with ``seed`` that seed's in the latest seed set; a set of
    several seeds needs ``seed`` (each seed is a model of its own)."""
    with db.read_session() as session:
        submission = session.get(Submission, submission_id)
        if submission is None:
            raise NotFound(f"no submission {submission_id}")
        latest = seed_sets.latest_set(submission)
        if seed is None and len(latest) > 1:
            raise InvalidInput(
                f"submission {submission_id} was trained with {len(latest)} seeds: choose one "
                f"with --seed (0 to {len(latest) - 1})"
            )
        if seed is None:
            job = training.latest_trained(submission)
        else:
            job = next((j for j in latest if j.seed == seed), None)
        if job is None or job.model_key is None:
            which = "" if seed is None else f" for seed {seed}"
            raise NotFound(f"submission {submission_id} has no trained output{which}")
        return TrainedModel(job.model_key, job.model_sha256, job.model_size, job.attempt, job.seed)


def scoring_profile(name: str) -> ScoringProfile:
    try:
        return load_profile(name)
    except ProfileError as exc:
        raise InvalidInput(str(exc)) from exc


@dataclass(frozen=True)
class RescoreTarget:
    run_id: int
    submission_id: int
    attempt: int
    phase: str


def rescore_targets(
    db: Database,
    settings: Settings,
    *,
    submission_id: int | None = None,
    phase: str | None = None,
    profile: str | None = None,
) -> list[RescoreTarget]:
    """Scored runs to re-score: one submission's, one phase's, or (neither given) every one.

    A run is always scored by its phase's profile, so a leaderboard never ranks one submission
    by other formulas than the rest. ``profile`` therefore changes a whole phase: it is set as
    the phase's profile (``phase`` required) and every scored run of the phase is re-scored."""
    if profile is not None:
        if phase is None or submission_id is not None:
            raise InvalidInput(
                "--profile changes the formulas a whole phase is ranked by: give --phase NAME "
                "(alone), and every scored submission of that phase is re-scored with it. One "
                "submission scored by other formulas than the rest of its leaderboard would be "
                "ranked unfairly"
            )
        scoring_profile(profile)
        phases.set_phase(db, settings, phase, phases.PhaseChanges(scoring_profile=profile))
    with db.read_session() as session:
        if phase is not None:
            phases.get_phase(session, phase)
        query = (
            select(
                EvaluationRun.id,
                EvaluationRun.submission_id,
                EvaluationRun.attempt,
                Submission.phase,
            )
            .join(Submission, Submission.id == EvaluationRun.submission_id)
            .where(EvaluationRun.status == RunStatus.scored)
        )
        if submission_id is not None:
            if session.get(Submission, submission_id) is None:
                raise NotFound(f"no submission {submission_id}")
            query = query.where(EvaluationRun.submission_id == submission_id)
        if phase is not None:
            query = query.where(Submission.phase == phase)
        rows = session.execute(query.order_by(EvaluationRun.id)).all()
        return [RescoreTarget(*row) for row in rows]


def rescore_run(
    db: Database, evaluation_settings: EvaluationSettings, store: ArtifactStore, run_id: int
) -> tuple[str, dict[str, float]]:
    """Recompute a scored run from its stored records (no simulation) with its phase's profile;
    returns the profile's name and the metrics."""
    with db.session() as session:
        run = lock(session, EvaluationRun, run_id)
        if run.status != RunStatus.scored:
            raise Conflict(f"run {run_id} is {run.status}; only scored runs can be re-scored")
        phase = phases.get_phase(session, run.submission.phase)
        profile = scoring_profile(phases.scoring_profile(phase, evaluation_settings))
        summary = scoring.run_summary(run, profile, store)
        if summary.uncharged:
            raise Conflict(
                f"submission {run.submission_id} (run {run_id}): the records of "
                f"{', '.join(summary.uncharged)} cannot be scored"
            )
        run_score = scoring.run_score(summary)
        if run_score is None:
            raise Conflict(
                f"submission {run.submission_id} (run {run_id}) has no charged scenario to score"
            )
        run.scoring_profile = profile.name
        run.scoring_version = str(profile.version)
        evaluation.write_score(session, run, run_score, profile.name, str(profile.version))
        return profile.name, run_score.metrics


def comparison_side(db: Database, submission_id: int) -> Side:
    """A submission's standing score as one side of ``arena admin compare``: its metrics,
    interval, families and every episode's outcome (hidden phases included: organisers only).
    Over several training seeds: the seed set's metrics, interval and families, the seeds'
    spread, and each seed's run with its own metrics and outcomes."""
    with db.read_session() as session:
        submission = session.get(Submission, submission_id)
        if submission is None:
            raise NotFound(f"no submission {submission_id}")
        score = seed_sets.standing_score(submission)
        if score is None:
            raise Conflict(f"submission {submission_id} is {submission.status}: no score yet")
        runs = seed_sets.seed_runs(session, submission, score)
        interval = submissions.completion_interval(score)
        common = {
            "metrics": _compared_metrics(score),
            "interval": Interval(interval.low, interval.high) if interval else None,
            "families": {
                family: _compared_metrics(values) for family, values in score.families.items()
            },
            "suite": runs[0][1].manifest_sha256,
            "samples": MetricSamples.from_json(score.samples) if score.samples else None,
        }
        who = f"submission {submission.id} of {submission.team.name} ({submission.phase}"
        if not isinstance(score, SeedSetScore):
            ((_, run),) = runs
            return Side(
                label=f"{who}, attempt {run.attempt}, {submission.method_name})",
                outcomes=_outcomes(run),
                **common,
            )
        return Side(
            label=f"{who}, {len(runs)} training seeds, {submission.method_name})",
            seeds=tuple(
                SeedRun(seed, _compared_metrics(run.score), _outcomes(run)) for seed, run in runs
            ),
            spread=Spread(
                low=score.seed_completion_min,
                high=score.seed_completion_max,
                std=score.seed_completion_std,
            ),
            **common,
        )


def _compared_metrics(values) -> ScoringMetrics:
    """The four metrics of a score, a seed set's score or a family's (a mapping)."""
    get = values.get if isinstance(values, dict) else lambda name: getattr(values, name)
    return ScoringMetrics(**{name: get(name) for name in METRIC_NAMES})


def _outcomes(run: EvaluationRun) -> dict[str, str]:
    return {
        Episode(result.scenario_id, result.episode).name: outcome_text(
            [result.reason] if result.reason else [], str(result.status)
        )
        for result in run.results
    }


@dataclass(frozen=True)
class StuckRun:
    run_id: int
    submission_id: int
    worker: str
    lease_expires_at: datetime | None


@dataclass(frozen=True)
class Overdue:
    """A submission in one state longer than ``ARENA_OVERDUE_AFTER_S``."""

    submission_id: int
    team: str
    phase: str
    status: str
    since: datetime


@dataclass(frozen=True)
class LostSeed:
    """A training seed lost on our side: it waits for ``arena admin submissions requeue``."""

    submission_id: int
    seed: int
    lost: str  # "training" or "evaluation"


@dataclass(frozen=True)
class ServiceStatus:
    queue_depth: int | None
    workers: list[str] | None
    submissions: dict[str, int]
    running_runs: int
    stuck_runs: list[StuckRun]
    overdue: list[Overdue]
    # Phases nothing can be evaluated in, with why.
    broken_phases: dict[str, str]
    lost_seeds: list[LostSeed]
    # The simulator's per-step core (sim.compiled.core_status) in this process, as this
    # installation runs it (the embedded worker of `arena up` runs this one), and in each worker
    # that answered (None: the broker cannot ask them).
    simulator_core: str
    worker_cores: dict[str, str] | None


def service_status(db: Database, settings: Settings, queue: TaskQueue) -> ServiceStatus:
    with db.read_session() as session:
        counts = dict(
            session.execute(
                select(Submission.status, func.count()).group_by(Submission.status)
            ).all()
        )
        active = list(
            session.scalars(select(EvaluationRun).where(EvaluationRun.status.in_(list(ACTIVE_RUN))))
        )
        moment = utcnow()
        stuck = [
            StuckRun(run.id, run.submission_id, run.worker, run.lease_expires_at)
            for run in active
            if run.lease_expires_at is not None and run.lease_expires_at < moment
        ]
        running = sum(run.status == RunStatus.running for run in active)
        overdue = _overdue(session, moment - timedelta(seconds=settings.service.overdue_after_s))
        broken = phases.misconfigured(session, settings)
        lost = _lost_seeds(session)
    try:
        depth = queue.depth()
        workers = queue.workers()
        cores = queue.worker_cores(len(workers)) if workers else None
    except BROKER_ERRORS:  # reported as unreachable, not a crash
        depth = workers = cores = None
    return ServiceStatus(
        queue_depth=depth,
        workers=workers,
        submissions={str(status): counts.get(status, 0) for status in SubmissionStatus},
        running_runs=running,
        stuck_runs=stuck,
        overdue=overdue,
        broken_phases=broken,
        lost_seeds=lost,
        simulator_core=core_status(),
        worker_cores=cores,
    )


def _lost_seeds(session) -> list[LostSeed]:
    """Seeds of submissions under way that were lost on our side, training or evaluation."""
    going = session.scalars(
        select(Submission)
        .where(Submission.status.in_([SubmissionStatus.training, SubmissionStatus.running]))
        .order_by(Submission.id)
    )
    lost = []
    for submission in going:
        lost += [
            LostSeed(submission.id, j.seed, "training") for j in seed_sets.lost_seeds(submission)
        ]
        lost += [
            LostSeed(submission.id, j.seed, "evaluation")
            for j in seed_sets.lost_evaluations(submission)
        ]
    return lost


def _overdue(session, before: datetime) -> list[Overdue]:
    """Submissions waiting (queued since, or training / running since they started) longer
    than they should: whatever the reason, an organiser should look."""
    rows = session.scalars(
        select(Submission)
        .where(Submission.status.in_(list(ACTIVE_SUBMISSION)))
        .order_by(Submission.id)
    )
    late = []
    for submission in rows:
        since = submission.started_at or submission.queued_at or submission.created_at
        if submission.status in (SubmissionStatus.received, SubmissionStatus.queued):
            since = submission.queued_at or submission.created_at
        if since < before:
            late.append(
                Overdue(
                    submission.id,
                    submission.team.name,
                    submission.phase,
                    str(submission.status),
                    since,
                )
            )
    return late
