"""Submissions: accept an upload, show it to its team, cancel, disqualify, re-queue."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime, time
from pathlib import Path

from sqlalchemy import func, or_, select
from sqlalchemy.orm import Session, selectinload

from arena.config import Settings
from arena.errors import IntakeError
from arena.neutralise.names import UnsafeName, check_name
from arena.outcome import FINISHED, UNCHARGED, ScenarioStatus
from evaluator.provenance import Manifest, PublicManifest, over_seeds
from server.core.artifacts import artifact_store
from server.core.db import Database
from server.core.queue import BROKER_ERRORS, TaskQueue, scenario_task_id
from server.models import (
    EvaluationRun,
    ScenarioResult,
    Score,
    SeedSetScore,
    Submission,
    TrainingJob,
    utcnow,
)
from server.schemas import (
    AgentCpu,
    Attempt,
    CompletionInterval,
    FamilyMetrics,
    Metrics,
    Progress,
    ScenarioLog,
    SeedFailureReasons,
    SubmissionDetail,
    SubmissionLogs,
    SubmissionSummary,
    TrainingProgress,
)
from server.services import hidden_timing, validation
from server.services.errors import (
    Conflict,
    Forbidden,
    InvalidInput,
    InvalidUpload,
    NotFound,
    QuotaExceeded,
)
from server.services.evaluation import agent_cpu_used, bump_leaderboard, cancel_run, lock
from server.services.phases import (
    DEFAULT_PHASE,
    PhaseMisconfigured,
    check_open,
    check_team_may_see_output,
    daily_quota,
    get_phase,
    list_phases,
    phase_setup,
    team_sees_everything,
)
from server.services.seed_sets import (
    cancel_trainings,
    current_run,
    seed_results,
    seed_runs,
    set_runs,
    several,
    standing_score,
)
from server.services.training import shown_training
from server.status import (
    ACTIVE_RUN,
    ACTIVE_SUBMISSION,
    ACTIVE_TRAINING,
    SUBMISSION_MOVES,
    SubmissionStatus,
    advance,
)
from server.tracks import Track
from submissions.intake.archive import check_directory

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NewSubmission:
    track: Track
    method_name: str
    description: str = ""
    phase: str = DEFAULT_PHASE


def quota_used(session: Session, team_id: int, phase: str, track: Track, moment: datetime) -> int:
    """Submissions of the phase and the UTC day so far that count: every one being validated or
    accepted (rejected ones by the validation do not), failed ones
    included (an agent that crashes costs its team a try, or a crash would buy free evaluations
    of the hidden suite), except those that failed on our side, those whose agent could not be
    loaded (no scenario reached it: nothing of the suite to learn) and those cancelled before
    their evaluation started."""
    day_start = datetime.combine(moment.date(), time.min, tzinfo=moment.tzinfo)
    return session.scalar(
        select(func.count())
        .select_from(Submission)
        .where(
            Submission.team_id == team_id,
            Submission.phase == phase,
            Submission.track == track,
            Submission.created_at >= day_start,
            Submission.status != SubmissionStatus.rejected,
            or_(
                Submission.status != SubmissionStatus.failed,
                Submission.failed_on_our_side.is_(False),
            ),
            Submission.never_started.is_(False),
            or_(
                Submission.status != SubmissionStatus.cancelled, Submission.started_at.is_not(None)
            ),
        )
    )


def check_quota(
    session: Session, settings: Settings, team_id: int, phase: str, track: Track
) -> None:
    """Refuse an upload outside the phase's dates, beyond its daily quota, or once the team used
    its validation time today."""
    moment = utcnow()
    try:
        definition = get_phase(session, phase)
    except NotFound as exc:
        raise InvalidUpload(f"phase: {exc.message}") from None
    check_open(definition, moment)
    try:  # nothing could evaluate it: refused before it costs the team a try
        phase_setup(definition, settings)
    except PhaseMisconfigured as exc:
        log.error("upload to a broken phase refused: %s", exc.message)
        raise Forbidden(
            f"phase {phase!r} cannot evaluate submissions right now (the organisers' setup of "
            "it is broken; they are told by `arena admin status`); try again later"
        ) from None
    validation.check_budget(session, settings.intake, team_id)
    limit = daily_quota(definition, settings.service)
    if quota_used(session, team_id, phase, track, moment) >= limit:
        raise QuotaExceeded(
            f"daily quota of the {phase!r} phase reached: {limit} submissions per team and "
            "track per UTC day (only those that failed on our side or were cancelled before "
            "they started do not count)"
        )


def check_names(new: NewSubmission) -> str:
    """The method name to store; refuses what cannot be stored or shown safely."""
    method_name = new.method_name.strip()
    if not method_name or len(method_name) > 128:
        raise InvalidUpload("method_name: give the method a name of 1 to 128 characters")
    try:
        check_name("method_name", method_name)
    except UnsafeName as exc:
        raise InvalidUpload(str(exc)) from None
    # PostgreSQL cannot store a NUL; no other control character belongs in a description either.
    bad = next((c for c in new.description if ord(c) < 32 and c not in "\t\n\r"), None)
    if bad is not None:
        raise InvalidUpload(f"description: control character {bad!r} is not allowed")
    return method_name


def accept_upload(
    db: Database,
    settings: Settings,
    queue: TaskQueue,
    team_id: int,
    new: NewSubmission,
    upload: Path,
    sha256: str,
) -> Submission:
    """Reserve the team's validation slot and a try of its quota (atomically, first), run the
    cheap checks of the zip at ``upload`` (its directory), store it and queue its validation.

    What the request does is bounded by the zip's size; everything else (inflating, nested
    archives, compiling, requirements) is the validation job's, in the sandbox. A zip that fails
    the cheap checks leaves no trace."""
    method_name = check_names(new)
    if new.track == Track.offline and settings.training.train_dataset_dir is None:
        raise InvalidUpload(
            "track: this service cannot train offline submissions yet (no dataset: the "
            "organisers set ARENA_TRAIN_DATASET_DIR to a folder of `arena dataset build`)"
        )
    fields = {
        "phase": new.phase,
        "track": new.track,
        "method_name": method_name,
        "description": new.description.strip(),
    }

    def quota(session: Session) -> None:
        check_quota(session, settings, team_id, new.phase, new.track)

    submission_id, key = validation.reserve(db, settings.service, team_id, fields, quota)
    store = artifact_store(settings.storage, db)
    try:
        try:
            check_directory(upload, settings.intake)
        except IntakeError as exc:
            raise InvalidUpload(str(exc)) from exc
        store.put(key, upload)
        validation.stored(db, submission_id, sha256, upload.stat().st_size)
    except BaseException:
        store.delete_prefix(str(Path(key).parent))
        validation.give_back(db, submission_id)
        raise
    # After the commit: a worker that picks the task up finds the row. If the broker is down the
    # reaper sends it later.
    try:
        queue.validate(submission_id)
    except BROKER_ERRORS as exc:
        log.warning("queueing the validation of submission %s failed: %s", submission_id, exc)
    with db.read_session() as session:
        return get_submission(session, submission_id)


def keys_in_work(session: Session) -> tuple[set[str], set[str]]:
    """The zips and trained outputs of submissions still being trained or evaluated: what a
    worker keeps unpacked; the rest of its scratch can go. By their runs and trainings, not only
    their status: a re-run (or re-training) of a scored submission keeps showing its score while
    it works, and removing its unpacked zip under it failed its episodes as the team's."""
    evaluating = select(EvaluationRun.submission_id).where(EvaluationRun.status.in_(ACTIVE_RUN))
    training = select(TrainingJob.submission_id).where(TrainingJob.status.in_(ACTIVE_TRAINING))
    working = or_(
        Submission.status.in_(
            [SubmissionStatus.queued, SubmissionStatus.training, SubmissionStatus.running]
        ),
        Submission.id.in_(evaluating),
        Submission.id.in_(training),
    )
    uploads = set(session.scalars(select(Submission.upload_key).where(working)))
    models = set(
        session.scalars(
            select(TrainingJob.model_key)
            .join(Submission, TrainingJob.submission_id == Submission.id)
            .where(working, TrainingJob.model_key.is_not(None))
        )
    )
    return uploads, models


def get_submission(session: Session, submission_id: int) -> Submission:
    submission = session.get(Submission, submission_id)
    if submission is None:
        raise NotFound(f"no submission {submission_id}")
    return submission


def list_submissions(
    session: Session, team_id: int | None = None, limit: int = 100
) -> list[SubmissionSummary]:
    query = (
        select(Submission)
        .options(
            selectinload(Submission.team),
            selectinload(Submission.runs).selectinload(EvaluationRun.score),
            selectinload(Submission.runs).selectinload(EvaluationRun.training),
            selectinload(Submission.seed_set_scores),
        )
        .order_by(Submission.id.desc())
        .limit(limit)
    )
    if team_id is not None:
        query = query.where(Submission.team_id == team_id)
    rows = list(session.scalars(query))
    shown = [_shown_runs(submission) for submission in rows]
    done = finished_counts(session, [r.id for _, runs in shown for r in runs])
    hidden = hidden_phases(session)
    return [
        SubmissionSummary(
            **_summary_fields(submission, run, runs, done, submission.phase in hidden)
        )
        for submission, (run, runs) in zip(rows, shown, strict=True)
    ]


def rerunning(session: Session) -> set[int]:
    """Ids of the submissions with an evaluation run under way (a scored one keeps its old score
    meanwhile)."""
    active = select(EvaluationRun.submission_id).where(EvaluationRun.status.in_(list(ACTIVE_RUN)))
    return set(session.scalars(active))


def hidden_phases(session: Session) -> set[str]:
    """Names of the phases whose suite is hidden from the teams."""
    return {phase.name for phase in list_phases(session) if not team_sees_everything(phase)}


def live_in_hidden_phase(run: EvaluationRun | None, hidden: bool) -> bool:
    """A run of a hidden phase not yet over: its team sees no per-episode detail of it."""
    return hidden and run is not None and run.status in ACTIVE_RUN


def shown_progress(
    run: EvaluationRun | None, runs: list[EvaluationRun], done: dict[int, int], hidden: bool
) -> Progress:
    """Episodes done of ``total`` over ``runs``, the shown ``run``'s seed set (a seed without a
    run yet counts the episodes it will have); while a hidden phase's run is under way only in
    quarters of the run: per-episode progress would time each hidden episode for its team
    (:mod:`server.services.hidden_timing`)."""
    if run is None:
        return Progress(done=0, total=0)
    seeds = run.training.seeds if several(run.training) else 1
    total = sum(r.episode_count for r in runs) + (seeds - len(runs)) * run.episode_count
    finished = sum(done.get(r.id, 0) for r in runs)
    if any(live_in_hidden_phase(r, hidden) for r in runs):
        return hidden_timing.quarter_progress(finished, total, seeds)
    return Progress(done=finished, total=total, seeds=seeds)


def finished_counts(session: Session, run_ids: list[int]) -> dict[int, int]:
    """Finished scenarios per run, in one query."""
    if not run_ids:
        return {}
    rows = session.execute(
        select(ScenarioResult.run_id, func.count())
        .where(ScenarioResult.run_id.in_(run_ids), ScenarioResult.status.in_(list(FINISHED)))
        .group_by(ScenarioResult.run_id)
    ).all()
    return dict(rows)


def active_run(submission: Submission) -> EvaluationRun | None:
    active = [run for run in submission.runs if run.status in ACTIVE_RUN]
    return active[-1] if active else None


def shown_run(submission: Submission) -> EvaluationRun | None:
    """The run whose progress is shown: the one in progress, else the one whose score stands."""
    return active_run(submission) or current_run(submission)


def exact_progress(session: Session, submission: Submission) -> Progress:
    """Episodes done of the shown run's seed set, counted exactly (the organisers' view: its
    team sees a hidden phase's run under way only in quarters)."""
    run, runs = _shown_runs(submission)
    return shown_progress(run, runs, finished_counts(session, [r.id for r in runs]), hidden=False)


def _shown_runs(submission: Submission) -> tuple[EvaluationRun | None, list[EvaluationRun]]:
    """The shown run and its seed set's runs (itself alone but for several seeds)."""
    run = shown_run(submission)
    return run, (set_runs(submission, run) if run is not None else [])


def summary(session: Session, submission: Submission) -> SubmissionSummary:
    return SubmissionSummary(**_fields(session, submission))


def _fields(session: Session, submission: Submission) -> dict:
    run, runs = _shown_runs(submission)
    done = finished_counts(session, [r.id for r in runs])
    hidden = submission.phase in hidden_phases(session)
    return _summary_fields(submission, run, runs, done, hidden)


def _summary_fields(
    submission: Submission,
    run: EvaluationRun | None,
    runs: list[EvaluationRun],
    done: dict[int, int],
    hidden: bool,
) -> dict:
    score = standing_score(submission)
    finished_at, duration_s = submission.finished_at, _duration_s(submission)
    if hidden:  # a clock of the hidden run: coarse, and only once it ended
        finished_at = None
        if submission.status in ACTIVE_SUBMISSION or duration_s is None:
            duration_s = None
        else:
            duration_s = hidden_timing.coarse_s(duration_s)
    return {
        "id": submission.id,
        "team": submission.team.name,
        "phase": submission.phase,
        "track": submission.track,
        "method_name": submission.method_name,
        "status": submission.status,
        "created_at": submission.created_at,
        "queued_at": submission.queued_at,
        "started_at": submission.started_at,
        "finished_at": finished_at,
        "duration_s": duration_s,
        "progress": shown_progress(run, runs, done, hidden),
        "metrics": Metrics.model_validate(score) if score is not None else None,
        "completion_interval": completion_interval(score),
        # Of the run whose progress is shown: what the progress counts.
        "episodes_per_scenario": run.episodes_per_scenario if run is not None else 1,
        "seeds": seed_results(score),
    }


def _duration_s(submission: Submission) -> float | None:
    if submission.started_at is None:
        return None
    if submission.finished_at is None and submission.status not in ACTIVE_SUBMISSION:
        return None  # finished before finish times were kept
    end = submission.finished_at or utcnow()
    return max(0.0, (end - submission.started_at).total_seconds())


def completion_interval(score: Score | SeedSetScore | None) -> CompletionInterval | None:
    if score is None or score.completion_low is None or score.completion_high is None:
        return None
    return CompletionInterval(low=score.completion_low, high=score.completion_high)


def latest_attempt(submission: Submission) -> Attempt | None:
    """The state of the submission's latest run: REST shows it beside the score that stands."""
    if not submission.runs:
        return None
    run = submission.runs[-1]  # in attempt order
    return Attempt(attempt=run.attempt, status=run.status, error=run.error)


def detail(session: Session, submission: Submission) -> SubmissionDetail:
    """Everything its own team may see. Never hands out hidden scenario ids; in a hidden phase,
    no failure reason before the run is over (read live, episode by episode, the reasons an agent
    chose to fail with would carry what it saw of the hidden scenarios). Over several training
    seeds, the failure counts and the manifest cover every seed's run."""
    run = current_run(submission)
    standing = standing_score(submission)
    runs = seed_runs(session, submission, standing)
    results = [result for _, seed_run in runs for result in seed_run.results]
    if failed_on_our_side_while_hidden(session, submission, results):
        # The other episodes' per-family outcomes would tell the team about the hidden suite
        # at no cost (the run is not charged): nothing per family until it is rerun and scored.
        runs, standing = [], None
    hidden = submission.phase in hidden_phases(session)
    if any(live_in_hidden_phase(seed_run, hidden) for _, seed_run in runs):
        runs = []
    per_seed = [(seed, failure_counts(seed_run.results)) for seed, seed_run in runs]
    return SubmissionDetail(
        **_fields(session, submission),
        description=submission.description,
        status_reason=submission.status_reason,
        file_sha256=submission.file_sha256,
        file_size=submission.file_size,
        attempt=run.attempt if run is not None else 0,
        latest_attempt=latest_attempt(submission),
        scoring_profile=standing.profile if standing is not None else None,
        families={
            family: FamilyMetrics.model_validate(values)
            for family, values in (standing.families if standing is not None else {}).items()
        },
        failure_reasons=summed_counts([counts for _, counts in per_seed]),
        seed_failure_reasons=[
            SeedFailureReasons(seed=seed, failure_reasons=counts)
            for seed, counts in per_seed
            if seed is not None
        ],
        training=_training(submission),
        agent_cpu=_agent_cpu(session, _shown_runs(submission)[1], hidden),
        manifest=_manifest(runs if standing is not None else []),
    )


FailureCounts = dict[str, dict[str, int]]  # family -> failure reason -> episodes


def failure_counts(results: list[ScenarioResult]) -> FailureCounts:
    """The finished episodes that did not reach the goal, by family and reason."""
    counts: FailureCounts = {}
    for result in results:
        if result.status != ScenarioStatus.running and result.reason != "reached_goal":
            by_reason = counts.setdefault(result.family, {})
            reason = result.reason or result.status
            by_reason[reason] = by_reason.get(reason, 0) + 1
    return {family: counts[family] for family in sorted(counts)}


def summed_counts(each: list[FailureCounts]) -> FailureCounts:
    total: FailureCounts = {}
    for counts in each:
        for family, reasons in counts.items():
            by_reason = total.setdefault(family, {})
            for reason, count in reasons.items():
                by_reason[reason] = by_reason.get(reason, 0) + count
    return {family: total[family] for family in sorted(total)}


def _manifest(runs: list[tuple[int | None, EvaluationRun]]) -> PublicManifest | None:
    """The standing score's manifest as its team sees it: its run's, or over several seeds one
    listing each seed's model; None when a run's score was written before manifests."""
    manifests = {
        seed: Manifest.model_validate(seed_run.score.manifest)
        for seed, seed_run in runs
        if seed_run.score is not None and seed_run.score.manifest
    }
    if not manifests or len(manifests) < len(runs):
        return None
    if None in manifests:
        return manifests[None].public()
    return over_seeds(manifests).public()


def _agent_cpu(session: Session, runs: list[EvaluationRun], hidden: bool) -> AgentCpu | None:
    """The CPU the agent used so far in ``runs`` (the shown run, or its seed set's) against the
    budget each runs under; None before a run, for a run made before budgets were recorded, and
    while a hidden phase's run is under way (read after each episode, an agent's CPU would carry
    what it saw of hidden scenarios)."""
    if (
        not runs
        or any(run.evaluation_cpu_s is None for run in runs)
        or any(live_in_hidden_phase(run, hidden) for run in runs)
    ):
        return None
    used = [agent_cpu_used(session, run.id) for run in runs]
    if hidden:  # CPU an agent chose to burn is a clock too
        used = [hidden_timing.coarse_cpu_s(seconds) for seconds in used]
    return AgentCpu(
        used_s=sum(used),
        budget_s=max(run.evaluation_cpu_s for run in runs),
        evaluations=len(runs),
        most_used_s=max(used),
    )


def failed_on_our_side_while_hidden(
    session: Session, submission: Submission, results: list[ScenarioResult]
) -> bool:
    """Whether an episode of a run whose per-scenario results the team may not see ended on
    our side (uncharged)."""
    if not any(result.status in UNCHARGED for result in results):
        return False
    return not team_sees_everything(get_phase(session, submission.phase))


def _training(submission: Submission) -> TrainingProgress | None:
    job = shown_training(submission)
    return TrainingProgress.model_validate(job) if job is not None else None


def logs(session: Session, submission: Submission, *, organiser: bool = False) -> SubmissionLogs:
    """The agent's output tail per finished scenario. Its team sees it only in a phase of full
    visibility; in a hidden phase it goes to the organisers only. Scenario ids are shown where
    the suite is public to the reader."""
    phase = get_phase(session, submission.phase)
    if not organiser:
        check_team_may_see_output(phase)
    run = current_run(submission)
    entries = []
    # One ordinal per scenario of a family (its episodes share it), in the order they started.
    ordinal: dict[str, dict[str, int]] = {}
    results = sorted(run.results, key=lambda r: (r.family, r.id)) if run is not None else []
    for result in results:
        numbers = ordinal.setdefault(result.family, {})
        number = numbers.setdefault(result.scenario_id, len(numbers) + 1)
        if result.status == ScenarioStatus.running:
            continue
        label = f"{result.family} #{number}"
        if run.episodes_per_scenario > 1:
            label += f" episode {result.episode}"
        entries.append(
            ScenarioLog(
                label=label,
                scenario_id=result.scenario_id,
                episode=result.episode,
                family=result.family,
                status=result.status,
                reason=result.reason,
                log_tail=result.log_tail,
            )
        )
    return SubmissionLogs(submission_id=submission.id, scenarios=entries)


def cancel(db: Database, queue: TaskQueue, submission_id: int) -> Submission:
    """Stop a submission that has not finished: queued tasks are revoked and the workers kill
    its running sandboxes (they see the cancelled run on their next lease heartbeat)."""
    with db.session() as session:
        submission = lock(session, Submission, submission_id)
        if submission.status not in ACTIVE_SUBMISSION:
            raise Conflict(f"submission {submission_id} is {submission.status}; cannot cancel")
        submission.status = advance(submission.status, SubmissionStatus.cancelled, SUBMISSION_MOVES)
        submission.finished_at = utcnow()
        cancel_trainings(submission)
        unfinished: list[str] = []
        for run in submission.runs:
            if run.status in ACTIVE_RUN:
                unfinished += [scenario_task_id(run.id, e) for e in cancel_run(session, run)]
    queue.revoke(unfinished)
    return submission


def disqualify(db: Database, queue: TaskQueue, submission_id: int, reason: str) -> Submission:
    """Take a submission off the leaderboard for good, telling its team why (``reason`` is
    required: a bare "disqualified" leaves the team guessing)."""
    reason = reason.strip()
    if not reason:
        raise InvalidInput("give the reason the team is shown (--reason)")
    with db.session() as session:
        submission = lock(session, Submission, submission_id)
        if submission.status == SubmissionStatus.disqualified:
            raise Conflict(
                f"submission {submission_id} is already disqualified "
                f"(reason: {submission.status_reason or 'none given'})"
            )
        submission.status = advance(
            submission.status, SubmissionStatus.disqualified, SUBMISSION_MOVES
        )
        submission.status_reason = reason
        submission.finished_at = submission.finished_at or utcnow()
        cancel_trainings(submission)
        unfinished: list[str] = []
        for run in submission.runs:
            if run.status in ACTIVE_RUN:
                unfinished += [scenario_task_id(run.id, e) for e in cancel_run(session, run)]
        bump_leaderboard(session)
    queue.revoke(unfinished)
    return submission
