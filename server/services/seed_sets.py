"""Seed sets: an offline submission trained several times, one training job per seed (the
phase's ``training_seeds``), each trained model evaluated by its own run; the submission is
scored once every seed's run is, over the seeds (:mod:`evaluator.scoring.seeds`).

A set of one seed is what every offline submission had before seeds: its run's score is the
submission's, as for a freestyle submission. Any seed's failure fails the submission.
"""

from __future__ import annotations

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
from server.models import EvaluationRun, Score, SeedSetScore, Submission, TrainingJob
from server.models import utcnow as now
from server.schemas import SeedMetrics, SeedResults
from server.services import leases
from server.status import (
    ACTIVE_RUN,
    ACTIVE_TRAINING,
    TRAINING_MOVES,
    RunStatus,
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


def cancel_trainings(submission: Submission) -> None:
    """Cancel the submission's active trainings (every seed of its set in progress): their
    workers see it on the next heartbeat and kill the sandbox."""
    for job in submission.trainings:
        if job.status in ACTIVE_TRAINING:
            job.status = advance(job.status, TrainingStatus.cancelled, TRAINING_MOVES)
            leases.drop(job)
            job.finished_at = now()


def set_jobs(session: Session, submission_id: int, seed_set: int) -> list[TrainingJob]:
    return list(
        session.scalars(
            select(TrainingJob)
            .where(TrainingJob.submission_id == submission_id, TrainingJob.seed_set == seed_set)
            .order_by(TrainingJob.seed)
        )
    )


def latest_set(submission: Submission) -> list[TrainingJob]:
    """The jobs of the submission's latest seed set, in seed order."""
    if not submission.trainings:
        return []
    newest = max(job.seed_set for job in submission.trainings)
    return sorted(
        (job for job in submission.trainings if job.seed_set == newest), key=lambda j: j.seed
    )


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
    return SeedResults(
        count=len(score.per_seed),
        completion_min=score.seed_completion_min,
        completion_max=score.seed_completion_max,
        completion_std=score.seed_completion_std,
        per_seed=[SeedMetrics.model_validate(seed) for seed in score.per_seed],
    )
