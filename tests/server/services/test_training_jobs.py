"""Training jobs as database transitions, on SQLite and PostgreSQL: the status only moves
forward, a lost worker's training is re-sent and its late result refused, a cancelled training
stops, and organisers retrain and re-run on the trained output."""

from __future__ import annotations

from datetime import timedelta

import pytest

from server.models import Submission, TrainingJob, utcnow
from server.services import evaluation, submissions, training
from server.services.errors import Conflict
from server.status import (
    SUBMISSION_MOVES,
    IllegalTransition,
    SubmissionStatus,
    TrainingStatus,
    advance,
)
from server.tracks import Track
from tests.server.builders import make_team, queued_submission


def offline(db) -> int:
    team_id, _ = make_team(db, "bc")
    return queued_submission(db, team_id, track=Track.offline)


def started(db, settings, submission_id: int) -> int | None:
    """The one training job of a phase of one seed; None when nothing started."""
    with db.session() as session:
        ids = training.start_training(session, settings.service, submission_id)
    assert len(ids) <= 1
    return ids[0] if ids else None


def claim(db, settings, training_id: int, worker: str):
    with db.session() as session:
        return training.claim_training(session, settings.service, training_id, worker)


def trained(db, settings, job, worker: str):
    with db.session() as session:
        return training.record_trained(
            session,
            settings,
            job,
            worker,
            elapsed_s=1.0,
            log_tail="saved",
            model_key="training/1/model.tar.gz",
            model_sha256="a" * 64,
            model_size=10,
        )


def status_of(db, submission_id: int) -> SubmissionStatus:
    with db.session() as session:
        return session.get(Submission, submission_id).status


def test_only_offline_submissions_train_and_only_once(db, settings):
    team_id, _ = make_team(db, "free")
    freestyle = queued_submission(db, team_id)
    assert started(db, settings, freestyle) is None
    sid = offline(db)
    assert started(db, settings, sid) is not None
    assert started(db, settings, sid) is None  # a duplicate delivery
    assert status_of(db, sid) == SubmissionStatus.training
    with pytest.raises(IllegalTransition):
        advance(
            SubmissionStatus.running, SubmissionStatus.training, SUBMISSION_MOVES
        )  # never backwards


def test_trained_output_starts_the_evaluation_of_that_output(db, settings):
    sid = offline(db)
    job = claim(db, settings, started(db, settings, sid), "w1")
    plan = trained(db, settings, job, "w1")
    assert plan is not None and plan.episodes
    assert status_of(db, sid) == SubmissionStatus.running
    with db.session() as session:
        first = plan.episodes[0]
        work = evaluation.claim_scenario(
            session,
            settings.service,
            settings.sandbox,
            plan.run_id,
            first.scenario_id,
            "w",
            first.index,
        )
    assert work.model_key == "training/1/model.tar.gz"  # the worker mounts this model
    assert trained(db, settings, job, "w1") is None  # a redelivery changes nothing


def test_a_dead_workers_training_is_resent_and_its_late_result_refused(db, settings):
    sid = offline(db)
    training_id = started(db, settings, sid)
    first = claim(db, settings, training_id, "w1")
    assert claim(db, settings, training_id, "w2") is None  # the lease is alive
    with db.session() as session:
        session.get(TrainingJob, training_id).lease_expires_at = utcnow() - timedelta(seconds=1)
    with db.session() as session:
        assert training.reap(session, settings.service, queue_empty=False) == (training_id,)
    second = claim(db, settings, training_id, "w2")
    assert second.claim_number == 2
    with db.session() as session:
        assert not training.heartbeat(session, settings.service, first, "w1", 5.0, "")  # fenced off
        assert training.heartbeat(session, settings.service, second, "w2", 5.0, "epoch 1")
    assert trained(db, settings, first, "w1") is None
    assert trained(db, settings, second, "w2") is not None


def test_a_failed_training_fails_the_submission_with_its_name(db, settings):
    sid = offline(db)
    job = claim(db, settings, started(db, settings, sid), "w1")
    with db.session() as session:
        assert training.record_failed(
            session, job, "w1", failure="train_timeout", error="ran past 10 s", log_tail="epoch 3"
        )
    with db.session() as session:
        submission = session.get(Submission, sid)
        assert submission.status == SubmissionStatus.failed
        assert submission.status_reason == "train_timeout: ran past 10 s"
        assert not submission.failed_on_our_side  # the team's: counts towards the quota


def test_cancelling_stops_the_training(db, settings, client):
    from server.core.queue import TaskQueue

    sid = offline(db)
    job = claim(db, settings, started(db, settings, sid), "w1")
    submissions.cancel(db, TaskQueue(settings), sid)
    with db.session() as session:
        assert not training.heartbeat(session, settings.service, job, "w1", 1.0, "")
        assert session.get(TrainingJob, job.training_id).status == TrainingStatus.cancelled
    assert trained(db, settings, job, "w1") is None


def test_retrain_is_a_new_attempt_and_rerun_uses_the_trained_output(db, settings, arena):
    sid = offline(db)
    job = claim(db, settings, started(db, settings, sid), "w1")
    plan = trained(db, settings, job, "w1")
    with db.session() as session:
        with pytest.raises(Conflict, match="only scored or failed"):
            training.retrain(session, settings.service, sid)
        submission = session.get(Submission, sid)
        submission.status = SubmissionStatus.scored
        for run in submission.runs:
            run.status = "scored"
    with db.session() as session:
        (rerun,) = evaluation.rerun(session, settings, sid)
    assert rerun.run_id != plan.run_id
    with db.session() as session:
        session.get(Submission, sid).runs[-1].status = "scored"
    assert "training attempt 2 queued" in arena("retrain", str(sid))
    with db.session() as session:
        jobs = session.get(Submission, sid).trainings
        assert [(j.attempt, j.status) for j in jobs] == [(1, "trained"), (2, "queued")]


def test_requeue_resends_a_training(db, settings):
    from server.core.queue import TaskQueue
    from server.services import admin

    sid = offline(db)
    started(db, settings, sid)
    queue = TaskQueue(settings)
    try:
        assert admin.requeue(db, settings, queue, sid) == "training re-sent"
    finally:
        queue.close()
