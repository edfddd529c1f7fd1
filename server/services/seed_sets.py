"""Seed sets: an offline submission trained several times, one training job per seed (the
phase's ``training_seeds``), each trained model evaluated by its own run; the submission is
scored once every seed's run is, over the seeds (:mod:`evaluator.scoring.seeds`).

A set of one seed is what every offline submission had before seeds: its run's score is the
submission's, as for a freestyle submission. A seed's failure through the submission's fault fails
it (the set can no longer be scored: the other seeds stop). A seed lost on our side (its training
job's retries used up or every worker that took it died, or episodes of its run failed on our
side) leaves the others going: that seed waits for an organiser's ``arena admin submissions
requeue``, which trains it again in the same set
(:func:`server.services.training.replace_lost_seeds`; a set's jobs are therefore the latest job
of each seed, :func:`latest_per_seed`) or evaluates its model again
(:func:`server.services.evaluation.rerun_lost_seeds`).
"""

from __future__ import annotations

from collections.abc import Iterable

from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from arena.errors import InfrastructureError
from evaluator.scoring import MetricSamples
from evaluator.scoring.seeds import (
    METRICS,
    completion_table,
    mean_families,
    mean_metrics,
    pooled_samples,
    seed_interval,
    spread,
)
from server.jobs import leases
from server.models import EvaluationRun, Score, SeedSetScore, Submission, TrainingJob
from server.models import utcnow as now
from server.schemas import SeedMetrics, SeedResults
from server.status import (
    ACTIVE_RUN,
    ACTIVE_TRAINING,
    TRAINING_MOVES,
    RunStatus,
    SubmissionStatus,
    TrainingStatus,
    advance,
)


class SeedsApart(InfrastructureError):
    """The seeds' runs were made on different suites (the phase's suite changed between them):
    they cannot be scored together (not the team's fault: an organiser re-runs them)."""


def several(job: TrainingJob | None) -> bool:
    """Whether ``job`` (a run's training; None for freestyle) belongs to a set of several seeds."""
    return job is not None and job.seeds > 1


def reason(job: TrainingJob | None, text: str) -> str:
    """A failure reason for the team, naming the seed when the submission trains several."""
    return f"seed {job.seed} (of {job.seeds}): {text}" if several(job) else text


def training_failed(job: TrainingJob, failure: str, error: str) -> str:
    """Why a submission failed when one of its seeds' ``train.py`` did: what to read and what
    to fix, for a set of several seeds."""
    said = reason(job, f"{failure}: {error}")
    if not several(job):
        return said
    return (
        f"{said}. Its training log is shown with the training (seed {job.seed}); the other "
        f"seeds were stopped. train.py must succeed with every ARENA_TRAIN_SEED from 0 to "
        f"{job.seeds - 1}: fix it and upload again"
    )


def seed_lost(job: TrainingJob, what: str, detail: str, again: str) -> str:
    """What the team reads while a seed lost on our side (its ``what`` failed, ``detail``
    saying how) waits for an organiser, who makes it go ``again``."""
    return reason(
        job,
        f"{what} failed on our side ({detail}), not the submission's fault; the other seeds go "
        f"on, and this seed {again} once an organiser re-sends it",
    )


def cancel_trainings(submission: Submission) -> None:
    """Cancel the submission's active trainings (every seed of its set in progress): their
    workers see it on the next heartbeat and kill the sandbox."""
    for job in submission.trainings:
        if job.status in ACTIVE_TRAINING:
            job.status = advance(job.status, TrainingStatus.cancelled, TRAINING_MOVES)
            leases.drop(job)
            job.finished_at = now()


def latest_per_seed(jobs: Iterable[TrainingJob]) -> list[TrainingJob]:
    """Of a set's jobs, each seed's latest (a seed lost on our side and trained again has two),
    in seed order."""
    by_seed = {job.seed: job for job in sorted(jobs, key=lambda j: j.attempt)}
    return [by_seed[seed] for seed in sorted(by_seed)]


def set_jobs(session: Session, submission_id: int, seed_set: int) -> list[TrainingJob]:
    return latest_per_seed(
        session.scalars(
            select(TrainingJob).where(
                TrainingJob.submission_id == submission_id, TrainingJob.seed_set == seed_set
            )
        )
    )


def latest_set(submission: Submission) -> list[TrainingJob]:
    """The jobs of the submission's latest seed set, each seed's latest, in seed order."""
    if not submission.trainings:
        return []
    newest = max(job.seed_set for job in submission.trainings)
    return latest_per_seed(job for job in submission.trainings if job.seed_set == newest)


def lost_seeds(submission: Submission) -> list[TrainingJob]:
    """The latest set's seeds that failed while the submission goes on: lost on our side (a
    failure through the submission's fault fails it), waiting for an organiser's requeue."""
    if submission.status not in (SubmissionStatus.training, SubmissionStatus.running):
        return []
    return [job for job in latest_set(submission) if job.status == TrainingStatus.failed]


def lost_evaluations(submission: Submission) -> list[TrainingJob]:
    """The latest set's trained seeds whose latest run failed while the submission goes on:
    lost on our side (a run failing through the submission's fault fails it), waiting for an
    organiser's requeue."""
    if submission.status != SubmissionStatus.running:
        return []
    lost = []
    for job in latest_set(submission):
        runs = [run for run in submission.runs if run.training_id == job.id]
        if job.status == TrainingStatus.trained and runs and runs[-1].status == RunStatus.failed:
            lost.append(job)
    return lost


def seed_runs(
    session: Session, submission: Submission, score: Score | SeedSetScore | None
) -> list[tuple[int | None, EvaluationRun]]:
    """The runs a score comes from, each with its training seed (None for a score of one run),
    in seed order: each seed's behind a score over seeds, the one run behind a run's score;
    with no score, the current run's set (each seed's latest scored run, else its latest run)
    while a set of several is under way, else the current run alone."""
    if isinstance(score, SeedSetScore):
        return [
            (seed["seed"], session.get(EvaluationRun, seed["run_id"])) for seed in score.per_seed
        ]
    if score is not None:
        return [(None, session.get(EvaluationRun, score.run_id))]
    run = current_run(submission)
    if run is None:
        return []
    if not several(run.training):
        return [(None, run)]
    chosen = []
    for job in set_jobs(session, submission.id, run.training.seed_set):
        runs = [r for r in submission.runs if r.training_id == job.id]
        scored = [r for r in runs if r.status == RunStatus.scored]
        if scored or runs:
            chosen.append((job.seed, (scored or runs)[-1]))
    return chosen


def set_runs(submission: Submission, run: EvaluationRun) -> list[EvaluationRun]:
    """The runs of ``run``'s seed set (just ``run`` for one seed or freestyle): each seed's run
    under way, else its latest, in seed order; a seed training again has none yet."""
    if not several(run.training):
        return [run]
    jobs = latest_per_seed(j for j in submission.trainings if j.seed_set == run.training.seed_set)
    chosen = []
    for job in jobs:
        runs = [r for r in submission.runs if r.training_id == job.id]
        active = [r for r in runs if r.status in ACTIVE_RUN]
        if runs:
            chosen.append((active or runs)[-1])
    return chosen


def current_run(submission: Submission) -> EvaluationRun | None:
    """The run whose score stands: the latest scored attempt, else the latest attempt."""
    scored = [run for run in submission.runs if run.status == RunStatus.scored]
    return (scored or submission.runs or [None])[-1]


def score_set(session: Session, submission_id: int, seed_set: int) -> bool:
    """Score the seed set from each seed's latest run if every one is scored (and none is still
    under way): True when it was, False while a seed is still to come. Raises
    :class:`SeedsApart` when the runs are on different suites."""
    jobs = set_jobs(session, submission_id, seed_set)
    runs = list(
        session.scalars(
            select(EvaluationRun)
            .where(EvaluationRun.training_id.in_([job.id for job in jobs]))
            .order_by(EvaluationRun.attempt)
        )
    )
    if any(run.status in ACTIVE_RUN for run in runs):
        return False
    latest = {run.training_id: run for run in runs}  # attempt order: the last one stays
    if len(jobs) < jobs[0].seeds or any(
        job.id not in latest or latest[job.id].status != RunStatus.scored for job in jobs
    ):
        return False
    chosen = [latest[job.id] for job in jobs]
    if len({run.manifest_sha256 for run in chosen}) > 1:
        raise SeedsApart
    scores = {
        s.run_id: s
        for s in session.scalars(select(Score).where(Score.run_id.in_([run.id for run in chosen])))
    }
    seed_scores = [scores[run.id] for run in chosen]
    samples = [MetricSamples.from_json(score.samples) for score in seed_scores]
    per_seed = [
        {
            "seed": job.seed,
            "training_id": job.id,
            "run_id": run.id,
            "model": job.model_sha256,  # byte-identical models: train.py ignored the seed
            **{name: getattr(score, name) for name in METRICS},
        }
        for job, run, score in zip(jobs, chosen, seed_scores, strict=True)
    ]
    interval = seed_interval(completion_table(samples))
    seeds_spread = spread([score.completion for score in seed_scores])
    session.execute(
        delete(SeedSetScore).where(
            SeedSetScore.submission_id == submission_id, SeedSetScore.seed_set == seed_set
        )
    )
    session.add(
        SeedSetScore(
            submission_id=submission_id,
            seed_set=seed_set,
            attempt=max(run.attempt for run in chosen),
            episodes_per_scenario=chosen[0].episodes_per_scenario,
            **mean_metrics(per_seed),
            completion_low=interval.low,
            completion_high=interval.high,
            seed_completion_min=seeds_spread.low,
            seed_completion_max=seeds_spread.high,
            seed_completion_std=seeds_spread.std,
            per_seed=per_seed,
            families=mean_families([score.families for score in seed_scores]),
            samples=pooled_samples(samples).to_json(),
            profile=seed_scores[0].profile,
            profile_version=seed_scores[0].profile_version,
        )
    )
    return True


def standing_score(submission: Submission) -> Score | SeedSetScore | None:
    """The score that stands for the submission: that of its latest complete evaluation, a
    seed set's (over several seeds) or a single run's."""
    single = [
        run
        for run in submission.runs
        if run.status == RunStatus.scored and run.score is not None and not several(run.training)
    ]
    over_seeds = submission.seed_set_scores[-1] if submission.seed_set_scores else None
    if over_seeds is not None and (not single or over_seeds.attempt > single[-1].attempt):
        return over_seeds
    return single[-1].score if single else None


def seed_results(score: Score | SeedSetScore | None) -> SeedResults | None:
    """What the team sees of the seeds behind a score; None for a score of one run."""
    if not isinstance(score, SeedSetScore):
        return None
    same = identical_models(score.per_seed)
    return SeedResults(
        count=len(score.per_seed),
        completion_min=score.seed_completion_min,
        completion_max=score.seed_completion_max,
        completion_std=score.seed_completion_std,
        per_seed=[SeedMetrics.model_validate(seed) for seed in score.per_seed],
        identical_models=same,
        ignores_seed=ignored_seed(same, len(score.per_seed)),
    )


def identical_models(per_seed: list[dict]) -> list[list[int]]:
    """Groups of seeds whose trained outputs are byte-identical (the same sha256 of the
    deterministic archive): whatever their evaluations say, those seeds trained one model."""
    by_model: dict[str, list[int]] = {}
    for seed in per_seed:
        if seed.get("model"):  # kept since seed sets record it; re-scoring adds it
            by_model.setdefault(seed["model"], []).append(seed["seed"])
    return sorted(seeds for seeds in by_model.values() if len(seeds) > 1)


def ignored_seed(same: list[list[int]], count: int) -> str:
    """Said instead of the seeds' spread when some of them trained the same model."""
    if not same:
        return ""
    groups = "; ".join(" and ".join(str(seed) for seed in seeds) for seeds in same)
    whole = len(same) == 1 and len(same[0]) == count
    return (
        f"train.py ignores the seed: {'every seed' if whole else 'seeds ' + groups} trained "
        "byte-identical models, so the spread over the seeds measures nothing; read "
        "ARENA_TRAIN_SEED and seed everything random with it (docs/training.md)"
    )
