"""The life of an evaluation run, as database transitions. Celery tasks, the reaper and the admin
CLI call these; each takes the row lock first and returns early when the work is already done, so
any of them can run twice (a redelivered task, a re-queue) without double-counting anything.

Callers send the tasks these functions ask for only after the function's transaction committed.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path

from sqlalchemy import delete, func, select, update
from sqlalchemy.orm import Session

from arena.config import SandboxSettings, ServiceSettings, Settings
from arena.cpu_limits import CpuLimits
from arena.episodes import Episode, episode_count, episodes_of
from arena.errors import SuiteError
from arena.outcome import FINISHED, AgentOutcome, ScenarioStatus
from arena.suite import Suite, load_suite
from evaluator import failures
from evaluator.runner import ScenarioOutcome
from evaluator.scoring import load_profile
from server.core.artifacts import ArtifactStore
from server.core.queue import RunPlan
from server.jobs import leases
from server.jobs.leases import lease_until
from server.models import (
    EvaluationRun,
    LeaderboardGeneration,
    ScenarioResult,
    Score,
    Submission,
    TrainingJob,
)
from server.models import utcnow as now
from server.services import hidden_timing, phases, scoring, seed_sets
from server.services.errors import Conflict, NotFound
from server.status import (
    ACTIVE_RUN,
    RUN_MOVES,
    SUBMISSION_MOVES,
    RunStatus,
    SubmissionStatus,
    TrainingStatus,
    advance,
)
from server.tracks import Track

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ScenarioJob:
    """What a worker needs to run one episode of one scenario of a run."""

    run_id: int
    submission_id: int
    scenario_id: str
    scenario_dir: str
    upload_key: str  # the submission's zip in the artifact store
    claim_number: int  # 1 for the first claim; more after workers died holding it
    episode: int = 0  # arena.episodes: which traffic seed
    model_key: str | None = None  # the trained output it evaluates (offline submissions)
    limits: CpuLimits | None = None  # the run's agent CPU limits (None: the settings')

    @property
    def key(self) -> Episode:
        return Episode(self.scenario_id, self.episode)

    def __str__(self) -> str:
        return f"{self.key.name} of run {self.run_id} (claim {self.claim_number})"


def lock(session: Session, model, row_id: int):
    """The row of ``model`` with id ``row_id``, locked (:func:`server.jobs.leases.locked`)."""
    row = leases.locked(session, model, model.id == row_id)
    if row is None:
        raise NotFound(f"no {model.__tablename__[:-1].replace('_', ' ')} {row_id}")
    return row


def bump_leaderboard(session: Session) -> None:
    updated = session.execute(
        update(LeaderboardGeneration)
        .where(LeaderboardGeneration.id == 1)
        .values(value=LeaderboardGeneration.value + 1)
    )
    if updated.rowcount == 0:
        session.add(LeaderboardGeneration(id=1, value=1))


def _suite(folder: Path) -> Suite:  # a run's own suite, fixed when it was created
    try:
        return load_suite(folder)
    except SuiteError as exc:
        raise NotFound(str(exc)) from exc


def create_run(
    session: Session,
    settings: Settings,
    submission: Submission,
    training: TrainingJob | None = None,
) -> RunPlan:
    """A new attempt on the suite of the submission's phase; every episode of it still to run.
    ``training``: the trained output it evaluates (offline submissions). (The whole settings:
    the phase's defaults come from several groups, the lease from the service's.)"""
    phase = phases.get_phase(session, submission.phase)
    setup = phases.phase_setup(phase, settings)
    limits = phases.cpu_limits(phase, settings.sandbox)
    suite, profile, per_scenario = setup.suite, setup.profile, setup.episodes_per_scenario
    episodes = episodes_of(suite.scenarios, per_scenario)
    attempt = 1 + (
        session.scalar(
            select(func.max(EvaluationRun.attempt)).where(
                EvaluationRun.submission_id == submission.id
            )
        )
        or 0
    )
    run = EvaluationRun(
        submission_id=submission.id,
        attempt=attempt,
        status=RunStatus.queued,
        suite_dir=str(suite.root),
        manifest_sha256=suite.sha256,
        episode_count=len(episodes),
        episodes_per_scenario=per_scenario,
        adaptive_target=phase.adaptive_target,
        max_episodes=phase.max_episodes if phase.adaptive_target is not None else None,
        episode_round=per_scenario,
        scoring_profile=profile.name,
        scoring_version=str(profile.version),
        lease_expires_at=lease_until(settings.service),
        training_id=training.id if training is not None else None,
        step_cpu_s=limits.step_s,
        episode_cpu_s=limits.episode_s,
        evaluation_cpu_s=limits.evaluation_s,
    )
    session.add(run)
    session.flush()
    return RunPlan(run_id=run.id, episodes=episodes, aggregate=not episodes)


def start_evaluation(session: Session, settings: Settings, submission_id: int) -> RunPlan | None:
    """First attempt of a queued submission; None if it is no longer queued (done already,
    cancelled, or a duplicate delivery of the same task)."""
    submission = lock(session, Submission, submission_id)
    if submission.status != SubmissionStatus.queued:
        return None
    try:
        phases.phase_setup(phases.get_phase(session, submission.phase), settings)
    except (phases.PhaseMisconfigured, NotFound) as exc:
        cannot_start(submission, exc.message)
        return None
    submission.status = advance(submission.status, SubmissionStatus.running, SUBMISSION_MOVES)
    submission.started_at = now()
    return create_run(session, settings, submission)


def cannot_start(submission: Submission, detail: str) -> None:
    """Fail a submission whose phase cannot start an evaluation, at once and saying so: left
    queued, the reaper would re-send it forever. The team's reason names no suite path (a
    hidden suite's place is the organisers'); the organisers read the detail in the log and in
    ``arena admin status``."""
    log.error("submission %d cannot start: %s", submission.id, detail)
    end_submission(
        submission,
        f"cannot be evaluated: the organisers' setup of phase {submission.phase!r} is broken "
        "(they are told); ask them to re-run it once fixed",
    )


def end_submission(
    submission: Submission,
    reason: str,
    *,
    ours: bool = False,
    status: SubmissionStatus = SubmissionStatus.failed,
) -> None:
    """Give a submission its outcome: ``failed`` (``rejected`` from its validation, ``scored``
    once its score is written), ``reason`` being what its team reads about it; ``ours``: failed
    through no fault of the team (the one failure that gives its daily quota try back)."""
    submission.status = advance(submission.status, status, SUBMISSION_MOVES)
    submission.status_reason = reason
    submission.failed_on_our_side = ours
    submission.finished_at = now()


def rerun(session: Session, settings: Settings, submission_id: int) -> tuple[RunPlan, ...]:
    """A new simulation attempt of a scored or failed submission (of an offline one, a run per
    seed of its latest seed set); its current score stands until the new attempt is scored."""
    submission = lock(session, Submission, submission_id)
    if submission.status not in (SubmissionStatus.scored, SubmissionStatus.failed):
        raise Conflict(
            f"submission {submission_id} is {submission.status}: only scored or failed "
            "submissions can be re-run"
        )
    if any(run.status in ACTIVE_RUN for run in submission.runs):
        raise Conflict(f"submission {submission_id} already has an evaluation in progress")
    if submission.track == Track.offline:
        jobs = seed_sets.latest_set(submission)
        if not jobs or any(job.status != TrainingStatus.trained for job in jobs):
            raise Conflict(
                f"submission {submission_id} has no trained output to evaluate for every seed: "
                "retrain it"
            )
        return tuple(create_run(session, settings, submission, training=job) for job in jobs)
    return (create_run(session, settings, submission),)


def rerun_lost_seeds(
    session: Session, settings: Settings, submission: Submission
) -> tuple[RunPlan, ...]:
    """A new run of each seed whose evaluation was lost on our side while the submission went
    on (:func:`server.services.seed_sets.lost_evaluations`): its trained model evaluated again."""
    plans = tuple(
        create_run(session, settings, submission, training=job)
        for job in seed_sets.lost_evaluations(submission)
    )
    if plans:
        submission.status_reason = ""  # it said the seed waits for an organiser
    return plans


def claim_scenario(
    session: Session,
    service: ServiceSettings,
    sandbox: SandboxSettings,
    run_id: int,
    scenario_id: str,
    worker: str,
    episode: int = 0,
) -> ScenarioJob | None:
    """Mark an episode of a scenario as being run by ``worker``; None if the run is over or the
    episode is finished or held by a worker whose lease is still valid."""
    run = lock(session, EvaluationRun, run_id)
    if run.status not in ACTIVE_RUN:
        return None
    existing = session.scalar(
        select(ScenarioResult).where(
            ScenarioResult.run_id == run_id,
            ScenarioResult.scenario_id == scenario_id,
            ScenarioResult.episode == episode,
        )
    )
    if existing is not None and (not existing.under_way or leases.held(existing)):
        return None
    suite = _suite(Path(run.suite_dir))
    entry = next((e for e in suite.scenarios if e.id == scenario_id), None)
    if entry is None:
        raise NotFound(f"scenario {scenario_id} is not in the suite of run {run_id}")
    if not 0 <= episode < episode_count(entry, run.episodes_per_scenario):
        raise NotFound(f"run {run_id} has no episode {episode} of scenario {scenario_id}")
    if existing is None:
        existing = ScenarioResult(
            run_id=run_id,
            scenario_id=scenario_id,
            episode=episode,
            family=entry.family.value,
            status=ScenarioStatus.running,
            claim_number=0,
        )
        session.add(existing)
    claim_number = leases.claim(existing, worker, service)
    if run.status == RunStatus.queued:
        run.status = advance(run.status, RunStatus.running, RUN_MOVES)
        run.started_at = now()
    leases.take(run, worker, service)
    return ScenarioJob(
        run_id=run_id,
        submission_id=run.submission_id,
        scenario_id=scenario_id,
        scenario_dir=str(suite.scenario_dir(scenario_id)),
        upload_key=run.submission.upload_key,
        claim_number=claim_number,
        episode=episode,
        model_key=run.training.model_key if run.training is not None else None,
        limits=run_cpu_limits(run, sandbox),
    )


def run_cpu_limits(run: EvaluationRun, sandbox: SandboxSettings) -> CpuLimits:
    """The CPU limits the run is evaluated under: those recorded when it was made (the
    sandbox settings' for a run made before they were)."""
    return sandbox.cpu_limits.overridden(run.step_cpu_s, run.episode_cpu_s, run.evaluation_cpu_s)


def agent_cpu_used(session: Session, run_id: int) -> float:
    """The CPU time [s] the agent's finished episodes of the run used together."""
    return session.scalar(
        select(func.coalesce(func.sum(ScenarioResult.agent_cpu_s), 0.0)).where(
            ScenarioResult.run_id == run_id, ScenarioResult.status.in_(list(FINISHED))
        )
    )


def heartbeat(session: Session, service: ServiceSettings, job: ScenarioJob, worker: str) -> bool:
    """Extend the lease of ``worker``'s claim on the job's scenario (and the run's); False when
    the claim is no longer this worker's (the run was cancelled, or the reaper gave the
    scenario to another worker): the episode must stop, its result would be refused."""
    claim = leases.renew(session, service, ScenarioResult, _claim_of(job, worker))
    run_fence = (EvaluationRun.id == job.run_id, EvaluationRun.status.in_(list(ACTIVE_RUN)))
    run = leases.renew(session, service, EvaluationRun, run_fence, worker=worker)
    return claim and run


def release_claim(session: Session, job: ScenarioJob, worker: str) -> bool:
    """Hand a scenario back (its worker is shutting down): another worker may claim it at once.
    False when the claim was no longer ``worker``'s."""
    return leases.release(session, ScenarioResult, _claim_of(job, worker))


def _claim_of(job: ScenarioJob, worker: str) -> tuple:
    """The fence of the episode's row: a superseded episode (its worker presumed dead) can never
    write into the live run."""
    return leases.fence(
        ScenarioResult,
        worker,
        job.claim_number,
        ScenarioResult.run_id == job.run_id,
        ScenarioResult.scenario_id == job.scenario_id,
        ScenarioResult.episode == job.episode,
    )


def record_scenario(
    session: Session,
    job: ScenarioJob,
    worker: str,
    outcome: ScenarioOutcome,
    log_tail: str,
    record_key: str | None = None,
) -> bool:
    """Store a finished scenario as the core reported it, if ``worker`` still holds the claim.
    Returns True exactly once per run: when this call finished its last scenario (the caller
    then sends the aggregation)."""
    run = lock(session, EvaluationRun, job.run_id)
    if run.status not in ACTIVE_RUN:
        return False
    values = scoring.result_values(outcome, log_tail, record_key)
    finished = session.execute(
        update(ScenarioResult)
        .where(*_claim_of(job, worker))
        .values(**values, worker="", lease_expires_at=None)
    )
    if finished.rowcount == 0:
        return False  # a duplicate delivery, or a superseded claim: the result is not ours
    if _give_up_if_agent_cannot_start(session, run):
        return False
    if job.limits is not None and _stop_over_cpu_budget(session, run, job.limits):
        return False
    return finished_count(session, job.run_id) == run.episode_count


def _give_up_if_agent_cannot_start(session: Session, run: EvaluationRun) -> bool:
    """Fail the run when its first finished scenarios all show the agent failing before its first
    step (import or init error, init timeout): one error for the team instead of one per scenario.
    The run's other scenario tasks find it inactive and do nothing. In a hidden phase the error
    names the failure, not the agent's own words (no byte the agent wrote reaches the team)."""
    results = session.scalars(
        select(ScenarioResult)
        .where(ScenarioResult.run_id == run.id, ScenarioResult.status.in_(list(FINISHED)))
        .order_by(ScenarioResult.id)
    ).all()
    if len(results) < failures.FAIL_FAST_AFTER or len(results) >= run.episode_count:
        return False
    agents = [[AgentOutcome(**a) for a in r.detail.get("agents", [])] for r in results]
    if not all(
        r.status == ScenarioStatus.done and failures.never_started(a)
        for r, a in zip(results, agents, strict=True)
    ):
        return False
    shown = str(results[0].reason)
    # Free only when no observation reached the agent: one that failed at its first act had seen
    # a scenario, and a free run would let it tell its team about the hidden suite for nothing.
    never_started = all(r.detail.get("observed") is False for r in results)
    phase = phases.get_phase(session, run.submission.phase)
    if phases.team_sees_everything(phase):
        error = failures.startup_error(results[0].log_tail).splitlines()
        shown = error[-1] if error else shown
    else:
        shown += " (evaluate in the validation phase or locally to see its output)"
    charge = (
        "it does not count against your daily quota"
        if never_started
        else "it counts against your daily quota: your agent failed after it was sent a scenario"
    )
    _fail_run(
        session,
        run,
        f"your agent could not start: {shown} "
        f"(the same in the first {len(results)} episodes; the others were not run; {charge})",
    )
    run.submission.never_started = never_started
    return True


def _stop_over_cpu_budget(session: Session, run: EvaluationRun, limits: CpuLimits) -> bool:
    """Fail the run, charged to the team, once its agent's episodes used more CPU than the
    evaluation's budget: the remaining episodes find it inactive and are not run."""
    used = agent_cpu_used(session, run.id)
    if not limits.over_budget(used):
        return False
    if phases.team_sees_everything(phases.get_phase(session, run.submission.phase)):
        told = limits.budget_exceeded(used, finished_count(session, run.id))
    else:  # the CPU an agent chose to burn, and where it stopped, would time hidden scenarios
        told = limits.budget_exceeded(hidden_timing.coarse_cpu_s(used), None)
    _fail_run(session, run, told)
    return True


def _fail_run(session: Session, run: EvaluationRun, error: str) -> None:
    """End an active run as failed through the submission's fault, with ``error`` as what its
    team reads."""
    run.error = error
    run.status = advance(run.status, RunStatus.failed, RUN_MOVES)
    run.finished_at = now()
    submission = lock(session, Submission, run.submission_id)
    if submission.status == SubmissionStatus.running:
        end_submission(submission, seed_sets.reason(run.training, run.error))
    stop_seed_set(session, submission)


def stop_seed_set(session: Session, submission: Submission) -> None:
    """A seed failed: the set can no longer be scored, so its other seeds' trainings and runs
    stop (their pending tasks find them inactive and do nothing)."""
    seed_sets.cancel_trainings(submission)
    for run in submission.runs:
        if run.status in ACTIVE_RUN:
            cancel_run(session, run)


def finished_count(session: Session, run_id: int) -> int:
    return session.scalar(
        select(func.count())
        .select_from(ScenarioResult)
        .where(
            ScenarioResult.run_id == run_id,
            ScenarioResult.status.in_(list(FINISHED)),
        )
    )


def finish_run(session: Session, store: ArtifactStore, run_id: int) -> RunStatus | None:
    """Score a run whose scenarios are all finished; None if it was finished already."""
    run = lock(session, EvaluationRun, run_id)
    if run.status not in ACTIVE_RUN:
        return None
    if finished_count(session, run_id) < run.episode_count:
        raise Conflict(f"run {run_id} still has scenarios to run")
    submission = lock(session, Submission, run.submission_id)
    summary = scoring.run_summary(run, load_profile(run.scoring_profile), store)
    run_score = None
    if summary.uncharged:
        # A score always covers the whole suite: what failed on our side waits for an organiser.
        run.error = (
            f"{len(summary.uncharged)} scenario(s) failed on our side (not the submission's "
            "fault); an organiser re-runs the evaluation"
        )
    else:
        run_score = scoring.run_score(summary)
        if run_score is None:
            run.error = "no scenario could be scored"
    run.finished_at = now()
    if run_score is None:
        run.status = advance(run.status, RunStatus.failed, RUN_MOVES)
        if summary.uncharged and seed_sets.several(run.training):
            # One seed's evaluation lost on our side: the other seeds go on, and this one
            # waits for an organiser's requeue (rerun_lost_seeds).
            if submission.status == SubmissionStatus.running:
                submission.status_reason = seed_sets.seed_lost(
                    run.training,
                    "evaluation",
                    f"{len(summary.uncharged)} scenario(s)",
                    "is evaluated again",
                )
            return run.status
        if submission.status == SubmissionStatus.running:
            end_submission(
                submission,
                seed_sets.reason(run.training, run.error),
                ours=bool(summary.uncharged),
            )
        stop_seed_set(session, submission)
        return run.status
    write_score(session, run, run_score, run.scoring_profile, run.scoring_version)
    run.status = advance(run.status, RunStatus.scored, RUN_MOVES)
    if seed_sets.several(run.training):
        session.flush()
        try:
            if not seed_sets.score_set(session, submission.id, run.training.seed_set):
                return run.status  # the submission is scored once its last seed is
        except seed_sets.SeedsApart:
            if submission.status == SubmissionStatus.running:
                end_submission(
                    submission,
                    "its seeds were evaluated on different suites (the phase's suite changed "
                    "meanwhile); an organiser re-runs the evaluation",
                    ours=True,
                )
            return run.status
    if submission.status in (SubmissionStatus.running, SubmissionStatus.failed):
        end_submission(submission, "", status=SubmissionStatus.scored)
    return run.status


def write_score(
    session: Session, run: EvaluationRun, run_score: scoring.RunScore, profile: str, version: str
) -> None:
    session.execute(delete(Score).where(Score.run_id == run.id))
    session.add(
        Score(
            run_id=run.id,
            profile=profile,
            profile_version=version,
            families=run_score.families,
            completion_low=run_score.completion_interval.low,
            completion_high=run_score.completion_interval.high,
            samples=run_score.samples,
            manifest=scoring.run_manifest(run, profile, version).model_dump(mode="json"),
            **run_score.metrics,
        )
    )
    bump_leaderboard(session)


def pending_episodes(run: EvaluationRun) -> tuple[Episode, ...]:
    """Episodes of the run that have no finished result yet, in manifest order."""
    done = {
        Episode(result.scenario_id, result.episode)
        for result in run.results
        if result.status in FINISHED
    }
    suite = _suite(Path(run.suite_dir))
    episodes = episodes_of(suite.scenarios, run.episodes_per_scenario)
    return tuple(episode for episode in episodes if episode not in done)


def cancel_run(session: Session, run: EvaluationRun) -> tuple[Episode, ...]:
    """Cancel an active run; returns its episodes that have not finished. Their claims go too:
    a cancelled run shows no scenario as running."""
    run.status = advance(run.status, RunStatus.cancelled, RUN_MOVES)
    run.finished_at = now()
    pending = pending_episodes(run)
    session.execute(
        delete(ScenarioResult).where(
            ScenarioResult.run_id == run.id, ScenarioResult.status == ScenarioStatus.running
        )
    )
    return pending


@dataclass(frozen=True)
class Reaped:
    """Work the reaper found lost: scenario tasks and aggregations to send again, and queued
    submissions whose first task never started."""

    plans: tuple[RunPlan, ...] = ()
    submission_ids: tuple[int, ...] = ()


def reap(session: Session, service: ServiceSettings, *, queue_empty: bool) -> Reaped:
    """Find work whose lease expired and return it to be sent again.

    A scenario whose worker stopped renewing its claim's lease is released and re-sent at once,
    whatever the rest of its run does. Work never claimed at all (a run whose own lease expired)
    is re-sent only when the queue is empty: until then it may just be waiting its turn (and a
    lost message is found as soon as the queue drains, e.g. after a broker restart without
    persistence).
    """
    moment = now()
    resend: dict[int, set[Episode]] = {}
    expired = (
        leases.expired(ScenarioResult)
        .join(EvaluationRun, EvaluationRun.id == ScenarioResult.run_id)
        .where(EvaluationRun.status.in_(list(ACTIVE_RUN)))
    )
    # An episode's task is lost with its run's (below), not on its own: no waiting episodes.
    stale, _ = leases.reap(session, service, expired, None)
    for claim in stale:
        resend.setdefault(claim.run_id, set()).add(Episode(claim.scenario_id, claim.episode))
    plans = [
        RunPlan(run_id=run_id, episodes=tuple(sorted(episodes)))
        for run_id, episodes in resend.items()
    ]
    if queue_empty:
        idle = session.scalars(
            select(EvaluationRun)
            .where(
                EvaluationRun.status.in_(list(ACTIVE_RUN)),
                EvaluationRun.lease_expires_at < moment,
                EvaluationRun.id.not_in(list(resend)),
            )
            .with_for_update()
        )
        for run in idle:
            pending = pending_episodes(run)
            run.lease_expires_at = lease_until(service)
            plans.append(RunPlan(run_id=run.id, episodes=pending, aggregate=not pending))
    submission_ids: list[int] = []
    if queue_empty:
        waiting = session.scalars(
            select(Submission)
            .where(
                Submission.status == SubmissionStatus.queued,
                Submission.queued_at < moment - timedelta(seconds=service.lease_seconds),
            )
            .with_for_update()
        )
        for submission in waiting:
            submission.queued_at = moment
            submission_ids.append(submission.id)
    return Reaped(plans=tuple(plans), submission_ids=tuple(submission_ids))
