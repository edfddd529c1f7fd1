"""The job engine's contract, through a job kind written for the test (as a new kind would be):
claim, heartbeat, fence, finish, hand back, our failures. The kind keeps its rows in memory;
the Celery task is real (run eagerly), and so is the worker's heartbeat thread."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any

import pytest
from celery import Celery

from arena.config import get_settings
from server.jobs import engine, heartbeat
from server.worker import local

WAIT_S = 10.0  # [s] a generous bound on what takes a heartbeat or two (0.5 s each here)


@dataclass(frozen=True)
class ToyClaim:
    job: str
    claim_number: int


@dataclass
class ToyJobs:
    """Rows in a dict; ``work(claim, lease)`` is the job's run."""

    work: Any
    name: str = "toy"
    max_claims: int = 2
    rows: dict[str, dict] = field(default_factory=dict)
    finished: list = field(default_factory=list)
    released: list = field(default_factory=list)
    resent: list = field(default_factory=list)
    renewed: list = field(default_factory=list)

    def claim(self, session, settings, worker, *, job):
        row = self.rows.setdefault(job, {"claims": 0, "live": True})
        if not row["live"]:
            return None
        row["claims"] += 1
        return ToyClaim(job, row["claims"])

    def renew(self, session, service, claim, worker, **progress):
        self.renewed.append(progress)
        return self.rows[claim.job]["live"]

    def release(self, session, claim, worker):
        self.released.append(claim)
        return True

    def send_again(self, queue, claim):
        self.resent.append(claim)

    def run(self, claim, lease, settings):
        return self.work(claim, lease)

    def ours(self, claim, reason, error):
        return ("ours", reason, error)

    def finish(self, claim, worker, result, settings):
        self.finished.append(result)

    def reap(self, service, queue, *, queue_empty):
        return 0


@pytest.fixture
def run(tmp_path, monkeypatch):
    """Runs a ToyJobs job through a real bound Celery task, eagerly."""
    monkeypatch.setenv("ARENA_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("ARENA_LEASE_SECONDS", "1")  # a renewal every 0.5 s
    for cache in (get_settings, local.database, local.queue, heartbeat.heartbeat):
        cache.cache_clear()
    app = Celery("engine-test", set_as_current=False)
    app.conf.task_always_eager = True

    def run_one(kind: ToyJobs, job: str = "a") -> None:
        @app.task(bind=True, max_retries=engine.INFRASTRUCTURE_RETRIES)
        def toy(self, *, job: str) -> None:
            engine.run_job(kind, self, get_settings(), local.worker(), job=job)

        toy.apply(kwargs={"job": job}, throw=True)

    yield run_one
    heartbeat.shutting_down.clear()
    for cache in (get_settings, local.database, local.queue, heartbeat.heartbeat):
        cache.cache_clear()


def until_stopped(claim, lease) -> str:
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        if lease.stopped:
            return "stopped"
        time.sleep(0.05)
    return "ran to the end"


def test_a_finished_job_is_renewed_with_progress_and_its_result_written(run):
    def work(claim, lease):
        lease.report(step=1)
        time.sleep(1.2)  # two renewals
        return "trained"

    kind = ToyJobs(work)
    run(kind)
    assert kind.finished == ["trained"]
    assert {"step": 1} in kind.renewed
    assert kind.released == [] and kind.resent == []


def test_a_lost_claim_stops_the_job_and_its_result_is_dropped(run):
    stopped = threading.Event()

    def work(claim, lease):
        lease.stop_with(stopped.set)
        kind.rows[claim.job]["live"] = False  # cancelled, or given to another worker
        return until_stopped(claim, lease)

    kind = ToyJobs(work)
    run(kind)
    assert stopped.is_set()
    assert kind.finished == [] and kind.resent == []


def test_a_stopping_worker_hands_the_job_back(run):
    def work(claim, lease):
        heartbeat.shutting_down.set()
        return until_stopped(claim, lease)

    kind = ToyJobs(work)
    run(kind)
    assert kind.finished == []
    assert kind.released == [ToyClaim("a", 1)] and kind.resent == [ToyClaim("a", 1)]


def test_a_crash_is_our_failure_naming_the_exception(run):
    def work(claim, lease):
        raise KeyError("boom")

    kind = ToyJobs(work)
    run(kind)
    [(ours, reason, error)] = kind.finished
    assert (ours, reason) == ("ours", "KeyError") and "boom" in error


def test_a_job_whose_workers_kept_dying_fails_as_ours_without_running(run):
    ran = []
    kind = ToyJobs(lambda claim, lease: ran.append(claim))
    kind.rows["a"] = {"claims": kind.max_claims, "live": True}
    run(kind)
    assert ran == []
    assert kind.finished == [("ours", engine.WORKER_LOST, "2 workers died holding it")]


def test_a_job_that_is_over_is_not_run(run):
    ran = []
    kind = ToyJobs(lambda claim, lease: ran.append(claim))
    kind.rows["a"] = {"claims": 1, "live": False}
    run(kind)
    assert ran == [] and kind.finished == []
