"""A training seed lost on our side, through the job engine and the real training job kind (its
claim, release, fence and finish on the test's database, PostgreSQL with Redis in the
integration tier): the engine retries that seed's job alone, and once its retries are used up (or
every worker that took it died) that seed waits for an organiser while the submission and its
other seeds go on. Only the sandbox is stood in for: it cannot be made unavailable to one seed."""

from __future__ import annotations

import pytest
from celery import Celery

from arena.config import get_settings
from arena.errors import SandboxUnavailable
from server.core.queue import TaskQueue
from server.jobs import engine, heartbeat
from server.models import Submission, TrainingJob
from server.services import admin
from server.status import RunStatus, SubmissionStatus, TrainingStatus
from server.worker import local
from server.worker.trainings import Trainings
from tests.server.live import export_settings
from tests.server.services.test_training_seeds import (
    claim,
    evaluate,
    offline,
    set_seeds,
    start,
    status_of,
    trained,
)


class SandboxDown(Trainings):
    """The training kind on a worker whose sandbox cannot start (what the engine retries)."""

    def __init__(self) -> None:
        self.tries = 0

    def run(self, claim, lease, settings):
        self.tries += 1
        raise SandboxUnavailable("the agent zygote did not start")


@pytest.fixture
def train(settings, db, monkeypatch):
    """Runs one training job through a real bound Celery task (eager, so its retries run at
    once) with the worker's settings naming this test's database, broker and folders."""
    export_settings(monkeypatch, settings)
    caches = (get_settings, local.database, local.queue, local.store, heartbeat.heartbeat)
    for cache in caches:
        cache.cache_clear()
    app = Celery("seed-failures-test", set_as_current=False)
    app.conf.task_always_eager = True

    def run_one(kind, training_id: int) -> None:
        @app.task(bind=True, max_retries=engine.INFRASTRUCTURE_RETRIES)
        def train_submission(self, *, training_id: int) -> None:
            engine.run_job(kind, self, get_settings(), local.worker(), training_id=training_id)

        # Not thrown: an eager task's retry is a Retry its apply() catches to apply it again.
        result = train_submission.apply(kwargs={"training_id": training_id}, throw=False)
        assert result.successful(), result.traceback

    yield run_one
    for cache in caches:
        cache.cache_clear()


def job(db, training_id: int) -> TrainingJob:
    with db.read_session() as session:
        return session.get(TrainingJob, training_id)


def test_a_seed_whose_sandbox_is_down_is_retried_alone_then_waits(db, settings, train):
    set_seeds(db, settings, 3)
    sid = offline(db)
    ids = start(db, settings, sid)
    plan0 = trained(db, settings, claim(db, settings, ids[0]))  # seed 0 trained: evaluating
    third = claim(db, settings, ids[2])  # seed 2 training on another worker
    down = SandboxDown()
    train(down, ids[1])
    assert down.tries == 1 + engine.INFRASTRUCTURE_RETRIES  # released and retried each time
    lost = job(db, ids[1])
    assert (lost.status, lost.failure, lost.claim_number) == (
        TrainingStatus.failed,
        "SandboxUnavailable",
        3,
    )
    with db.read_session() as session:
        submission = session.get(Submission, sid)
        assert submission.status == SubmissionStatus.running  # not failed, nothing charged
        assert not submission.failed_on_our_side
        assert "seed 1 (of 3): training failed on our side" in submission.status_reason
        assert [run.status for run in submission.runs] == [RunStatus.queued]  # seed 0's
    assert job(db, ids[2]).status == TrainingStatus.training  # seed 2 goes on
    assert evaluate(db, settings, plan0, fails=0) == RunStatus.scored
    assert evaluate(db, settings, trained(db, settings, third), fails=1) == RunStatus.scored
    assert status_of(db, sid) == SubmissionStatus.running  # waiting for seed 1
    queue = TaskQueue(settings)
    try:
        assert "seed(s) 1 lost on our side: trained again" in admin.requeue(
            db, settings, queue, sid
        )
    finally:
        queue.close()
    with db.read_session() as session:
        again = max(j.id for j in session.get(Submission, sid).trainings)
    assert job(db, again).seed == 1
    assert evaluate(db, settings, trained(db, settings, claim(db, settings, again)), 0) == (
        RunStatus.scored
    )
    assert status_of(db, sid) == SubmissionStatus.scored


def test_a_seed_whose_workers_kept_dying_waits_without_stopping_the_others(db, settings, train):
    set_seeds(db, settings, 2)
    sid = offline(db)
    ids = start(db, settings, sid)
    first = claim(db, settings, ids[0])
    with db.session() as session:  # every worker that took seed 1 died holding it
        session.get(TrainingJob, ids[1]).claim_number = Trainings.max_claims
    train(Trainings(), ids[1])
    lost = job(db, ids[1])
    assert (lost.status, lost.failure) == (TrainingStatus.failed, engine.WORKER_LOST)
    assert job(db, ids[0]).status == TrainingStatus.training
    assert status_of(db, sid) == SubmissionStatus.training
    trained(db, settings, first)  # seed 0's result is still taken
    assert status_of(db, sid) == SubmissionStatus.running
