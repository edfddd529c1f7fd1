"""Track 2 end to end with real processes: an offline submission uploaded over HTTP trains in
the bubblewrap sandbox on a dataset of real replays, is evaluated with its trained output and
ranked on the offline leaderboard; a training past its budget fails with its name; a worker
killed while training loses nothing: the training resumes from its last checkpoint; a phase of
two seeds trains and evaluates each and scores the submission over them; a worker lost on one
seed costs that seed a second claim and nothing else; a team's train.py failing on one seed
fails the submission and leaves nothing of the other seed running or stored."""

from __future__ import annotations

import hashlib
import io
import shutil
import signal
import subprocess
import tarfile
import time
import uuid
from pathlib import Path

import httpx
import pytest
from sqlalchemy import select

from arena.suite import SHIPPED_PUBLIC_DIR
from server.core.artifacts import artifact_store
from server.core.db import Database
from server.core.migrate import upgrade_database
from server.models import EvaluationRun, ScenarioResult, TrainingJob
from server.services.audit import audit
from server.worker.checkpoints import checkpoint_key
from submissions.intake import pack_folder
from tests.server.builders import EXAMPLES, bearer, make_team
from tests.server.conftest import ADMIN_TOKEN, REDIS_URL, _create_pg_database, _drop_pg_database
from tests.server.live import api_server, stop
from tests.server.service_stack import (
    SCENARIOS,
    build_small_suite,
    shared_dir,
    start_worker,
    wait_finished,
)
from tests.settings import env_only, evaluate_args

pytestmark = [pytest.mark.slow, pytest.mark.bwrap]

# A recorded replay of the public set: two vehicles, a few hundred real transitions.
DATASET_SCENARIO = "p033_replay_merge_2agents"


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    root = shared_dir("arena-train-suite-")
    yield build_small_suite(root)
    subprocess.run(["rm", "-rf", str(root)], check=False)


@pytest.fixture(scope="module")
def dataset():
    """A tiny dataset as `arena dataset build` writes it (its numpy export), from one replay."""
    from scenarios.dataset.build import TRANSITIONS, write_transitions
    from scenarios.dataset.collect import collect

    root = shared_dir("arena-train-dataset-")
    episodes, _ = collect(SHIPPED_PUBLIC_DIR / DATASET_SCENARIO)  # and why not others
    write_transitions(root / TRANSITIONS, episodes)
    (root / TRANSITIONS).chmod(0o644)
    yield root
    shutil.rmtree(root, ignore_errors=True)


@pytest.fixture
def stack_settings(suite, dataset, broker_prefix):
    name, url = _create_pg_database()
    upgrade_database(url)
    data = shared_dir("arena-train-data-")
    yield env_only(
        storage={"data_dir": data, "database_url": url, "broker_url": REDIS_URL},
        service={
            "broker_key_prefix": f"{broker_prefix}{uuid.uuid4().hex[:6]}:",
            "admin_token": ADMIN_TOKEN,
            "lease_seconds": 8,
            "reaper_interval_s": 2,
            "daily_quota": 10,
        },
        suites={"hidden_suite_dir": suite, "public_suite_dir": suite},
        sandbox={"kind": "bubblewrap"},
        training={
            "train_dataset_dir": dataset,
            "train_timeout_s": 25,
            "train_checkpoint_interval_s": 1,
        },
        evaluation={"jobs": 2},
    )
    _drop_pg_database(name)
    subprocess.run(["rm", "-rf", str(data)], check=False)


def offline_zip(out: Path, train_py: str | None = None) -> Path:
    """The offline_bc example, or it with ``train.py`` replaced (the original kept as
    ``bc_train.py`` for the replacement to run)."""
    folder = out / "src"
    shutil.copytree(EXAMPLES / "offline_bc", folder)
    if train_py is not None:
        (folder / "train.py").rename(folder / "bc_train.py")
        (folder / "train.py").write_text(train_py)
    return pack_folder(folder, out / "agent.zip")


def upload(url: str, token: str, path: Path, method: str) -> int:
    with path.open("rb") as handle:
        response = httpx.post(
            f"{url}/api/v1/submissions",
            headers=bearer(token),
            data={"track": "offline", "method_name": method},
            files={"file": (path.name, handle, "application/zip")},
            timeout=120,
        )
    assert response.status_code == 202, response.text
    return response.json()["id"]


def watch(url: str, token: str, submission_id: int, timeout_s: float = 300) -> list[dict]:
    """Every distinct (status, training status) the submission shows until it finishes."""
    seen: list[dict] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        body = httpx.get(
            f"{url}/api/v1/submissions/{submission_id}", headers=bearer(token), timeout=10
        ).json()
        if not seen or body["status"] != seen[-1]["status"]:
            seen.append(body)
        if body["status"] in ("scored", "failed", "rejected", "cancelled"):
            return seen
        time.sleep(0.3)
    raise AssertionError(f"submission {submission_id} did not finish: {seen[-1:]}")


def test_offline_submission_trains_then_is_evaluated_and_ranked(stack_settings, tmp_path):
    db = Database(stack_settings.storage.database_url)
    _, token = make_team(db, "bc-team")
    _, slow_token = make_team(db, "slow-team")
    worker = start_worker(stack_settings, tmp_path / "worker.log")
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            good = upload(url, token, offline_zip(tmp_path / "good"), "offline_bc")
            slow = upload(
                url,
                slow_token,
                offline_zip(tmp_path / "slow", "import time\nprint('epoch 1')\ntime.sleep(600)"),
                "forever",
            )
            statuses = watch(url, token, good)
            assert [s["status"] for s in statuses][-3:] == ["training", "running", "scored"]
            final = statuses[-1]
            assert final["progress"] == {
                "done": len(SCENARIOS),
                "total": len(SCENARIOS),
                "seeds": 1,
                "unit": "episodes",
            }
            training = final["training"]
            assert training["status"] == "trained" and training["failure"] == ""
            assert "saved weights.npz" in training["log_tail"]  # the team sees its log
            time.sleep(1.1)  # the API re-checks the leaderboard generation once a second
            board = httpx.get(f"{url}/api/v1/leaderboard", params={"track": "offline"}).json()
            assert [e["submission_id"] for e in board["entries"]] == [good]
            # The organisers' audit copy is the stored model, by its sha256.
            model = httpx.get(
                f"{url}/api/v1/admin/submissions/{good}/model", headers=bearer(ADMIN_TOKEN)
            )
            assert model.status_code == 200
            assert hashlib.sha256(model.content).hexdigest() == training["model_sha256"]
            assert model.headers["x-model-sha256"] == training["model_sha256"]
            # Its loss per epoch, logged to the metrics file, drawn for the organisers (a
            # hidden phase: not for the team); the file is no part of the model.
            curves = httpx.get(
                f"{url}/api/v1/admin/submissions/{good}/training.svg", headers=bearer(ADMIN_TOKEN)
            )
            assert curves.status_code == 200 and "<polyline" in curves.text
            assert ">loss<" in curves.text
            with tarfile.open(fileobj=io.BytesIO(model.content)) as archive:
                assert "training_metrics.csv" not in archive.getnames()

            failed = wait_finished(url, slow_token, slow)
            assert failed["status"] == "failed"
            assert failed["status_reason"].startswith("train_timeout")
            assert failed["training"]["failure"] == "train_timeout"
            assert "epoch 1" in failed["training"]["log_tail"]
            assert failed["progress"]["total"] == 0  # never evaluated
    finally:
        stop(worker)
    with db.session() as session:
        run = session.scalar(select(EvaluationRun).where(EvaluationRun.submission_id == good))
        assert run.training is not None and run.training.model_sha256 == training["model_sha256"]
    db.dispose()


# The offline_bc example with an epoch that takes a quarter of a second (60 epochs: 15 s), so
# that its worker can be killed mid-training.
SLOW_EPOCHS = """\
import runpy, time
import numpy as np

savez = np.savez


def slow_savez(*args, **kwargs):
    time.sleep(0.25)
    savez(*args, **kwargs)


np.savez = slow_savez
runpy.run_path("bc_train.py", run_name="__main__")
"""


def test_a_worker_killed_while_training_resumes_from_its_last_checkpoint(stack_settings, tmp_path):
    db = Database(stack_settings.storage.database_url)
    store = artifact_store(stack_settings.storage, db)
    _, token = make_team(db, "bc-team")
    worker = start_worker(stack_settings, tmp_path / "worker1.log", concurrency=1)
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload(url, token, offline_zip(tmp_path, SLOW_EPOCHS), "slow bc")
            wait_for_training(db, sid)
            training_id = training_of(db, sid)
            saved = checkpoint_key(training_id, claim=1)
            wait_until(lambda: store.exists(saved), "no checkpoint was saved while training ran")
            stop(worker, signal.SIGKILL)
            worker = start_worker(stack_settings, tmp_path / "worker2.log", concurrency=1)
            body = wait_finished(url, token, sid, timeout_s=300)
            assert body["status"] == "scored", body
            assert body["training"]["status"] == "trained"
            # The second claim's log: it started from the first one's checkpoint, not epoch 1.
            log_tail = body["training"]["log_tail"]
            resumed = [line for line in log_tail.splitlines() if line.startswith("resuming")]
            assert resumed and int(resumed[0].split()[-1]) >= 1, log_tail
            assert "epoch 1/" not in log_tail and "epoch 60/60" in log_tail
    finally:
        stop(worker)
    with db.session() as session:
        jobs = session.scalars(select(TrainingJob).where(TrainingJob.submission_id == sid)).all()
        assert [(j.attempt, j.claim_number, j.status) for j in jobs] == [(1, 2, "trained")]
        runs = session.scalars(select(EvaluationRun).where(EvaluationRun.submission_id == sid))
        assert len(runs.all()) == 1
    # Once trained, its checkpoints are gone from the store: only the model stays.
    assert not store.exists(saved) and not store.exists(checkpoint_key(training_id, claim=2))
    db.dispose()


def training_of(db: Database, submission_id: int) -> int:
    with db.session() as session:
        return session.scalar(
            select(TrainingJob.id).where(TrainingJob.submission_id == submission_id)
        )


def wait_until(condition, failure: str, timeout_s: float = 60) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.2)
    raise AssertionError(failure)


def wait_for_training(db: Database, submission_id: int, timeout_s: float = 60) -> None:
    """Until a worker holds the submission's training."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with db.session() as session:
            held = session.scalar(
                select(TrainingJob.worker).where(
                    TrainingJob.submission_id == submission_id, TrainingJob.status == "training"
                )
            )
        if held:
            return
        time.sleep(0.2)
    raise AssertionError("no worker took the training")


# The offline_bc example, saying which seed it trains with.
SEEDED = """\
import os, runpy
print("training with seed", os.environ["ARENA_TRAIN_SEED"], flush=True)
runpy.run_path("bc_train.py", run_name="__main__")
"""


def test_a_phase_of_two_seeds_trains_and_evaluates_each_and_scores_over_them(
    stack_settings, tmp_path
):
    from server.services import phases

    db = Database(stack_settings.storage.database_url)
    phases.set_phase(db, stack_settings, "final", phases.PhaseChanges(training_seeds=2))
    _, token = make_team(db, "bc-team")
    worker = start_worker(stack_settings, tmp_path / "worker.log")
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload(url, token, offline_zip(tmp_path / "seeded", SEEDED), "two seeds")
            final = watch(url, token, sid)[-1]
            assert final["status"] == "scored", final
            seeds = final["seeds"]
            assert seeds["count"] == 2 and [s["seed"] for s in seeds["per_seed"]] == [0, 1]
            mean = sum(s["completion"] for s in seeds["per_seed"]) / 2
            assert abs(final["metrics"]["completion"] - mean) < 1e-9
            time.sleep(1.1)  # the API re-checks the leaderboard generation once a second
            board = httpx.get(f"{url}/api/v1/leaderboard", params={"track": "offline"}).json()
            assert [e["seeds"]["count"] for e in board["entries"]] == [2]
    finally:
        stop(worker)
    with db.session() as session:
        jobs = session.scalars(select(TrainingJob).where(TrainingJob.submission_id == sid)).all()
        # Each job's sandbox had its own ARENA_TRAIN_SEED; each trained model had its own run.
        assert sorted(
            (job.seed, f"training with seed {job.seed}" in job.log_tail) for job in jobs
        ) == [(0, True), (1, True)]
        runs = session.scalars(
            select(EvaluationRun).where(EvaluationRun.submission_id == sid)
        ).all()
        assert sorted(run.training.seed for run in runs) == [0, 1]
        episodes = sum(run.episode_count for run in runs)
    # The audit re-runs each seed's model on its episodes; a changed record names its seed.
    store = artifact_store(stack_settings.storage, db)
    report = audit(db, store, sid, **evaluate_args(stack_settings))
    assert report.identical and report.compared == episodes, report
    with db.session() as session:
        run = session.scalar(
            select(EvaluationRun)
            .join(TrainingJob, EvaluationRun.training_id == TrainingJob.id)
            .where(EvaluationRun.submission_id == sid, TrainingJob.seed == 1)
        )
        result = session.scalar(
            select(ScenarioResult)
            .where(ScenarioResult.run_id == run.id, ScenarioResult.record_key.is_not(None))
            .order_by(ScenarioResult.scenario_id)
        )
        other = session.scalar(
            select(ScenarioResult).where(
                ScenarioResult.run_id != run.id,
                ScenarioResult.scenario_id != result.scenario_id,
                ScenarioResult.record_key.is_not(None),
            )
        )
        result.record_key = other.record_key  # seed 0's record stands in for seed 1's
        tampered = result.scenario_id
    report = audit(db, store, sid, **evaluate_args(stack_settings))
    assert report.difference is not None and report.difference.startswith("seed 1: "), report
    assert tampered in report.difference
    db.dispose()


def test_a_worker_killed_while_training_one_seed_retrains_that_seed_alone(stack_settings, tmp_path):
    """Two workers, one seed each; the one training seed 1 is killed: the reaper hands seed 1
    to the surviving worker (a second claim), seed 0 is never stopped, and the submission never
    fails: it is scored over both seeds."""
    import socket

    from server.services import phases

    db = Database(stack_settings.storage.database_url)
    phases.set_phase(db, stack_settings, "final", phases.PhaseChanges(training_seeds=2))
    _, token = make_team(db, "bc-team")
    workers = [
        start_worker(stack_settings, tmp_path / f"worker{k}.log", concurrency=1) for k in (1, 2)
    ]
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload(url, token, offline_zip(tmp_path, SLOW_EPOCHS), "slow bc, two seeds")

            def holders() -> dict[int, str]:
                with db.session() as session:
                    jobs = session.scalars(
                        select(TrainingJob).where(TrainingJob.submission_id == sid)
                    ).all()
                return {job.seed: job.worker for job in jobs if job.status == "training"}

            wait_until(lambda: all(holders().get(seed) for seed in (0, 1)), "seeds not taken")
            names = {f"{socket.gethostname()}:{w.pid}": w for w in workers}
            killed = names[holders()[1]]
            stop(killed, signal.SIGKILL)
            seen = watch(url, token, sid)
            assert [body["status"] for body in seen][-1] == "scored", seen[-1]
            assert "failed" not in [body["status"] for body in seen]
            assert seen[-1]["seeds"]["count"] == 2
    finally:
        for worker in workers:
            stop(worker)
    with db.session() as session:
        jobs = session.scalars(
            select(TrainingJob).where(TrainingJob.submission_id == sid).order_by(TrainingJob.seed)
        ).all()
        # Seed 0 trained once, on its first claim; seed 1 again on a second claim.
        assert [(j.seed, j.claim_number, j.status) for j in jobs] == [
            (0, 1, "trained"),
            (1, 2, "trained"),
        ]
    db.dispose()


# Seed 1's train.py fails a few seconds in; seed 0 trains slowly meanwhile (as SLOW_EPOCHS).
SEED_ONE_FAILS = (
    """\
import os, sys, time
if os.environ["ARENA_TRAIN_SEED"] == "1":
    time.sleep(4)
    sys.exit("seed 1 diverged")
"""
    + SLOW_EPOCHS
)


def test_a_seeds_train_py_failing_fails_the_submission_and_stops_the_other_seed(
    stack_settings, tmp_path
):
    """The team's train.py failing on seed 1 fails the submission saying which seed, where its
    log is and what to fix; seed 0, still training, is cancelled, its worker stops it and its
    checkpoints leave the store: nothing of the set is left behind."""
    from server.services import phases

    db = Database(stack_settings.storage.database_url)
    store = artifact_store(stack_settings.storage, db)
    phases.set_phase(db, stack_settings, "final", phases.PhaseChanges(training_seeds=2))
    _, token = make_team(db, "bc-team")
    worker = start_worker(stack_settings, tmp_path / "worker.log", concurrency=2)
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload(url, token, offline_zip(tmp_path, SEED_ONE_FAILS), "seed 1 fails")
            final = watch(url, token, sid)[-1]
            assert final["status"] == "failed", final
            reason = final["status_reason"]
            assert reason.startswith("seed 1 (of 2): train_error: "), reason
            assert "training log is shown with the training (seed 1)" in reason
            assert "ARENA_TRAIN_SEED from 0 to 1: fix it and upload again" in reason
            assert final["training"]["seed"] == 1 and "diverged" in final["training"]["log_tail"]

            def seed_zero():
                with db.session() as session:
                    return session.scalar(
                        select(TrainingJob).where(
                            TrainingJob.submission_id == sid, TrainingJob.seed == 0
                        )
                    )

            stopped = seed_zero()
            assert stopped.status == "cancelled"
            saved = checkpoint_key(stopped.id, claim=1)
            wait_until(lambda: not store.exists(saved), "the stopped seed's checkpoint stayed")
    finally:
        stop(worker)
    with db.session() as session:
        jobs = session.scalars(select(TrainingJob).where(TrainingJob.submission_id == sid)).all()
        assert sorted((j.seed, j.status) for j in jobs) == [(0, "cancelled"), (1, "failed")]
        assert (
            session.scalars(select(EvaluationRun).where(EvaluationRun.submission_id == sid)).all()
            == []
        )
    db.dispose()


def test_organiser_actions_on_a_seed_set_after_a_restart(stack_settings, tmp_path):
    """Track 2 over two seeds, the service restarted between the upload and each action: a
    re-run evaluates every seed's model again and gives the same scores, an audit re-runs them
    bit-identically, a requeue finds nothing lost and a re-score recomputes the same metrics."""
    from server.core.queue import TaskQueue
    from server.services import admin, phases
    from server.services.errors import Conflict

    db = Database(stack_settings.storage.database_url)
    queue = TaskQueue(stack_settings)
    phases.set_phase(db, stack_settings, "final", phases.PhaseChanges(training_seeds=2))
    _, token = make_team(db, "seeds-restarted")
    worker = start_worker(stack_settings, tmp_path / "worker-0.log")
    try:
        with api_server(stack_settings, tmp_path / "api-0.log") as (url, _):
            sid = upload(url, token, offline_zip(tmp_path / "seeded", SEEDED), "restarted")
            first = watch(url, token, sid)[-1]
        assert first["status"] == "scored", first
        stop(worker)
        worker = start_worker(stack_settings, tmp_path / "worker-1.log")
        admin.rerun(db, stack_settings, queue, sid)
        with db.session() as session:
            runs = session.scalars(
                select(EvaluationRun)
                .where(EvaluationRun.submission_id == sid)
                .order_by(EvaluationRun.attempt, EvaluationRun.id)
            ).all()
            # The re-run's, in seed order.
            run_ids = [run.id for run in sorted(runs[2:], key=lambda run: run.training.seed)]
        assert len(run_ids) == 2  # one per seed
        deadline = time.monotonic() + 300
        while True:
            with db.session() as session:
                states = [session.get(EvaluationRun, run_id).status for run_id in run_ids]
            if all(state not in ("queued", "running") for state in states):
                break
            assert time.monotonic() < deadline, states
            time.sleep(1)
        assert states == ["scored", "scored"]
        with api_server(stack_settings, tmp_path / "api-1.log") as (url, _):
            body = httpx.get(
                f"{url}/api/v1/submissions/{sid}", headers=bearer(token), timeout=10
            ).json()
        assert body["seeds"]["per_seed"] == first["seeds"]["per_seed"]
        assert body["latest_attempt"]["status"] == "scored"
        stop(worker)
        worker = start_worker(stack_settings, tmp_path / "worker-2.log")
        with pytest.raises(Conflict):
            admin.requeue(db, stack_settings, queue, sid)
        store = artifact_store(stack_settings.storage, db)
        rescored = [
            admin.rescore_run(db, stack_settings.evaluation, store, run_id)[1]["completion"]
            for run_id in run_ids
        ]
        assert rescored == [seed["completion"] for seed in first["seeds"]["per_seed"]]
        report = audit(db, store, sid, **evaluate_args(stack_settings))
        assert report.identical, report
    finally:
        stop(worker)
    db.dispose()
