"""The database half of the job engine, on a job table (``training_jobs``, as any table mixing
in LeasedJob), on SQLite and PostgreSQL: a claim counts and keeps others off while its lease
lives, only the current claim gets through the fence, and the reaper releases expired claims and
finds lost tasks."""

from __future__ import annotations

from datetime import timedelta

from sqlalchemy import update

from server.jobs import leases
from server.models import TrainingJob, utcnow
from server.status import ACTIVE_TRAINING, TrainingStatus
from server.tracks import Track
from tests.server.builders import make_team, queued_submission


def new_jobs(db, *statuses: TrainingStatus) -> list[int]:
    """Job rows of one submission, nobody holding them yet."""
    team_id, _ = make_team(db, "jobs")
    submission_id = queued_submission(db, team_id, track=Track.offline)
    with db.session() as session:
        jobs = [
            TrainingJob(submission_id=submission_id, attempt=number, status=status)
            for number, status in enumerate(statuses, start=1)
        ]
        session.add_all(jobs)
        session.flush()
        return [job.id for job in jobs]


def claim(db, settings, job_id: int, worker: str) -> int | None:
    with db.session() as session:
        job = leases.locked(session, TrainingJob, TrainingJob.id == job_id)
        return leases.claim(job, worker, settings.service)


def set_columns(db, job_id: int, **values) -> None:
    with db.session() as session:
        job = session.get(TrainingJob, job_id)
        for name, value in values.items():
            setattr(job, name, value)


def expire(db, job_id: int) -> None:
    """Its worker stopped renewing the lease (or nobody took its task in time)."""
    set_columns(db, job_id, lease_expires_at=utcnow() - timedelta(seconds=1))


def row(db, job_id: int) -> TrainingJob:
    with db.read_session() as session:
        return session.get(TrainingJob, job_id)


def test_a_claim_counts_and_its_live_lease_keeps_other_workers_off(db, settings):
    [job_id] = new_jobs(db, TrainingStatus.queued)
    assert claim(db, settings, job_id, "w1") == 1
    assert claim(db, settings, job_id, "w2") is None
    expire(db, job_id)  # w1 died
    assert claim(db, settings, job_id, "w2") == 2
    held = row(db, job_id)
    assert (held.worker, held.claim_number) == ("w2", 2) and leases.alive(held.lease_expires_at)


def test_a_claim_reads_the_row_as_locked_not_as_its_session_first_read_it(db, settings):
    [job_id] = new_jobs(db, TrainingStatus.queued)
    with db.session() as session:
        first_read = session.get(TrainingJob, job_id)
        assert not leases.held(first_read)
        # Another worker claims it meanwhile (written past this session's copy of the row).
        session.execute(
            update(TrainingJob)
            .where(TrainingJob.id == job_id)
            .values(
                worker="w2", claim_number=1, lease_expires_at=leases.lease_until(settings.service)
            ),
            execution_options={"synchronize_session": False},
        )
        job = leases.locked(session, TrainingJob, TrainingJob.id == job_id)
        assert leases.claim(job, "w1", settings.service) is None


def test_only_the_current_claim_renews_releases_and_owns_the_job(db, settings):
    [job_id] = new_jobs(db, TrainingStatus.training)
    claim(db, settings, job_id, "w1")
    expire(db, job_id)
    claim(db, settings, job_id, "w2")
    key = TrainingJob.id == job_id
    with db.session() as session:
        superseded = leases.fence(TrainingJob, "w1", 1, key)
        current = leases.fence(TrainingJob, "w2", 2, key)
        assert not leases.renew(session, settings.service, TrainingJob, superseded, elapsed_s=9.0)
        assert leases.renew(session, settings.service, TrainingJob, current, elapsed_s=1.0)
        assert not leases.release(session, TrainingJob, superseded)
        job = leases.locked(session, TrainingJob, key)
        assert leases.owned(job, "w2", 2)
        assert not leases.owned(job, "w1", 1) and not leases.owned(job, "w1", 2)
    assert (row(db, job_id).worker, row(db, job_id).elapsed_s) == ("w2", 1.0)
    set_columns(db, job_id, status=TrainingStatus.trained)  # no longer under way
    with db.session() as session:
        assert not leases.owned(session.get(TrainingJob, job_id), "w2", 2)
        assert not leases.release(session, TrainingJob, leases.fence(TrainingJob, "w2", 2, key))


def test_a_released_job_is_free_for_any_worker_at_once(db, settings):
    [job_id] = new_jobs(db, TrainingStatus.training)
    claim(db, settings, job_id, "w1")
    with db.session() as session:
        fence = leases.fence(TrainingJob, "w1", 1, TrainingJob.id == job_id)
        assert leases.release(session, TrainingJob, fence)
    assert claim(db, settings, job_id, "w2") == 2


def test_the_reaper_releases_expired_claims_and_finds_lost_tasks(db, settings):
    dead, lost, live, sent = new_jobs(
        db,
        TrainingStatus.training,
        TrainingStatus.queued,
        TrainingStatus.training,
        TrainingStatus.queued,
    )
    claim(db, settings, dead, "w1")
    expire(db, dead)  # its worker died
    expire(db, lost)  # its task was lost before any worker took it
    claim(db, settings, live, "w2")
    set_columns(db, sent, lease_expires_at=leases.lease_until(settings.service))  # just sent
    waiting = leases.unheld(TrainingJob).where(TrainingJob.status.in_(list(ACTIVE_TRAINING)))
    with db.session() as session:
        stale, found = leases.reap(session, settings.service, leases.expired(TrainingJob), waiting)
        assert ([job.id for job in stale], [job.id for job in found]) == ([dead], [lost])
    released = row(db, dead)
    assert (released.worker, released.lease_expires_at, released.claim_number) == ("", None, 1)
    assert leases.alive(row(db, lost).lease_expires_at)  # the re-sent task's lease
    assert row(db, live).worker == "w2"


def test_while_tasks_wait_in_the_queue_none_is_taken_for_lost(db, settings):
    [job_id] = new_jobs(db, TrainingStatus.queued)
    expire(db, job_id)
    with db.session() as session:
        stale, lost = leases.reap(session, settings.service, leases.expired(TrainingJob), None)
        assert (stale, lost) == ([], [])
