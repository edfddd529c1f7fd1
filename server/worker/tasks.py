"""Celery tasks of the service: thin wrappers around :mod:`server.services.evaluation`.

Every task is declared with :func:`arena_task` (late acknowledgement, requeue when the worker
process dies, one queue, time limits), takes keyword-only ids, returns early when the database
says its work is done, and sends follow-up tasks only after its transaction committed. Any task
can therefore be delivered twice: the unique (run, scenario, episode) row makes the second a
no-op.

``evaluate_submission`` fans out one ``run_scenario`` per episode of each scenario (several of
each reactive scenario when the phase asks for them); the ``run_scenario`` that finishes the last
one sends ``aggregate_run``, which scores the run from its stored records. An offline (Track 2)
submission first goes through ``train_submission``, which runs its ``train.py`` in the sandbox,
stores the trained output and then fans out the evaluation of that output.
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import threading
import time
import traceback
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from typing import Any

from celery import shared_task
from celery.signals import (
    worker_process_init,
    worker_ready,
    worker_shutdown,
    worker_shutting_down,
)
from sqlalchemy.exc import SQLAlchemyError

from arena.config import get_settings
from arena.errors import DatasetError, InfrastructureError, IntakeError
from evaluator.runner.scenario import ScenarioOutcome
from server.core.artifacts import ArtifactStore, artifact_store
from server.core.celery_app import (
    QUEUE,
    TASK_AGGREGATE,
    TASK_EVALUATE,
    TASK_SCENARIO,
    TASK_TRAIN,
    TASK_VALIDATE,
)
from server.core.db import get_database
from server.core.queue import BROKER_ERRORS, TaskQueue
from server.services import evaluation, training, validation
from server.tracks import Track

log = logging.getLogger(__name__)

# [s] One scenario: agent start-up plus the episode limit (600 s) plus a SUMO retry.
SCENARIO_TIME_LIMIT_S = 1800
BOOKKEEPING_TIME_LIMIT_S = 300
INFRASTRUCTURE_RETRIES = 2
# Claims of one scenario (a worker dying mid-scenario releases its claim) before giving up.
MAX_SCENARIO_ATTEMPTS = 3
# A backstop only (the thread pool enforces no task time limit): the training's own budget,
# ARENA_TRAIN_TIMEOUT_S, is enforced by evaluator.training.
TRAIN_TIME_LIMIT_S = 24 * 3600
MAX_TRAINING_CLAIMS = 3
# A backstop: each sandboxed step of a validation has ARENA_INTAKE_TIMEOUT_S, plus pip's download.
VALIDATE_TIME_LIMIT_S = 3600


def arena_task(name: str, *, time_limit: int, **options: Any):
    """The one decorator for service tasks."""
    return shared_task(
        name=name,
        queue=QUEUE,
        acks_late=True,
        reject_on_worker_lost=True,
        time_limit=time_limit,
        soft_time_limit=time_limit - 30,
        ignore_result=True,
        **options,
    )


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


@lru_cache(maxsize=1)
def _queue() -> TaskQueue:
    return TaskQueue(get_settings())


@arena_task(
    TASK_VALIDATE, time_limit=VALIDATE_TIME_LIMIT_S, bind=True, max_retries=INFRASTRUCTURE_RETRIES
)
def validate_submission(self, *, submission_id: int) -> None:
    """Validate an upload in the sandbox (evaluator.validation): ``queued`` and sent to
    evaluation, or ``rejected`` naming the rule it broke. Its scratch folder goes with it."""
    from evaluator.validation import validate
    from submissions.intake.archive import remove_tree
    from submissions.intake.dependencies import collect_garbage

    settings = get_settings()
    with get_database().read_session() as session:
        submission = validation.upload_of(session, submission_id)
        if submission is None:
            return
        upload_key, offline = submission.upload_key, submission.track == Track.offline
    folder = _scratch() / "validation" / str(submission_id)
    remove_tree(folder)
    try:
        zip_path = _store().fetch(upload_key, folder / "upload.zip")
        prepared = validate(
            zip_path,
            folder / "prepared",
            settings,
            kind=_sandbox_kind(),
            labels={"arena.validation": str(submission_id)},
            needs_training=offline,
        )
    except IntakeError as exc:
        with get_database().session() as session:
            rejected = validation.record_rejected(session, submission_id, str(exc), ours=False)
        if rejected:
            _store().delete_prefix(str(Path(upload_key).parent))
            with get_database().read_session() as session:
                collect_garbage(
                    settings, validation.deps_in_use(session), min_age_s=VALIDATE_TIME_LIMIT_S
                )
        return
    except InfrastructureError as exc:
        if self.request.retries < INFRASTRUCTURE_RETRIES:
            raise self.retry(exc=exc, countdown=10 * (self.request.retries + 1)) from exc
        with get_database().session() as session:
            validation.record_rejected(session, submission_id, f"validation: {exc}", ours=True)
        return
    finally:
        remove_tree(folder)
    with get_database().session() as session:
        valid = validation.record_valid(
            session, submission_id, deps_key=prepared.deps_key, explanation=prepared.explanation
        )
    if valid:
        _queue().evaluate(submission_id)


@arena_task(TASK_EVALUATE, time_limit=BOOKKEEPING_TIME_LIMIT_S)
def evaluate_submission(*, submission_id: int) -> None:
    settings = get_settings()
    with get_database().session() as session:
        # Offline submissions train first; the training's end starts their evaluation.
        training_id = training.start_training(session, settings, submission_id)
        plan = (
            evaluation.start_evaluation(session, settings, submission_id)
            if training_id is None
            else None
        )
    if training_id is not None:
        _queue().train(training_id)
    if plan is not None:
        _queue().send(plan)


@arena_task(
    TASK_TRAIN, time_limit=TRAIN_TIME_LIMIT_S, bind=True, max_retries=INFRASTRUCTURE_RETRIES
)
def train_submission(self, *, training_id: int) -> None:
    from evaluator.training import TrainingStopped

    settings = get_settings()
    me = worker_name()
    with get_database().session() as session:
        claim = training.claim_training(session, settings, training_id, me)
    if claim is None:
        return
    if claim.claim > MAX_TRAINING_CLAIMS:
        detail = f"{claim.claim - 1} workers died training it; an organiser can retrain it"
        _training_failed(claim, me, training.WORKER_LOST, detail, ours=True)
        return
    try:
        result = _train(claim, me)
    except TrainingStopped:
        if _shutting_down.is_set():
            _hand_back_training(claim, me)
        return  # otherwise the claim was lost: cancelled, or another worker has it
    except InfrastructureError as exc:
        if self.request.retries < INFRASTRUCTURE_RETRIES:
            with get_database().session() as session:
                training.release(session, claim, me)
            raise self.retry(exc=exc, countdown=10 * (self.request.retries + 1)) from exc
        _training_failed(claim, me, type(exc).__name__, str(exc), ours=True)
        return
    except DatasetError as exc:
        _training_failed(claim, me, "no_dataset", str(exc), ours=True)
        return
    except Exception:
        # A bug on our side: recorded (an organiser can retrain) rather than re-sent forever.
        log.exception("training %s crashed the task", training_id)
        _training_failed(claim, me, "evaluator_error", traceback.format_exc(), ours=True)
        return
    tail = _tail(result.log)
    if not result.ok:
        shutil.rmtree(_training_output(claim).parent, ignore_errors=True)
        with get_database().session() as session:
            training.record_failed(
                session,
                claim,
                me,
                failure=str(result.failure),
                error=result.detail,
                elapsed_s=result.elapsed_s,
                log_tail=tail,
            )
        return
    key, sha256, size = _store_model(claim)
    with get_database().session() as session:
        plan = training.record_trained(
            session,
            settings,
            claim,
            me,
            elapsed_s=result.elapsed_s,
            log_tail=tail,
            model_key=key,
            model_sha256=sha256,
            model_size=size,
        )
    if plan is not None:
        _queue().send(plan)


@arena_task(
    TASK_SCENARIO,
    time_limit=SCENARIO_TIME_LIMIT_S,
    bind=True,
    max_retries=INFRASTRUCTURE_RETRIES,
)
def run_scenario(self, *, run_id: int, scenario_id: str, episode: int = 0) -> None:
    settings = get_settings()
    db = get_database()
    me = worker_name()
    with db.session() as session:
        job = evaluation.claim_scenario(session, settings, run_id, scenario_id, me, episode)
    if job is None:
        return
    if job.attempt > MAX_SCENARIO_ATTEMPTS:
        # Every worker that took this scenario died with it (or was killed): stop handing it out.
        outcome = _our_failure(job, "worker_lost", f"{job.attempt - 1} workers died running it")
    else:
        try:
            run_key = _run_key(job)
            with _heartbeat(job, me, labels=_sandbox_labels(run_key)) as handed_back:
                outcome = _simulate(job, run_key)
            if handed_back.is_set():
                _hand_back(job, me)
                return
        except InfrastructureError as exc:
            if self.request.retries < INFRASTRUCTURE_RETRIES:
                raise self.retry(exc=exc, countdown=10 * (self.request.retries + 1)) from exc
            outcome = _our_failure(job, type(exc).__name__, str(exc))
        except Exception as exc:
            # A bug on our side: recorded (the run then fails visibly and can be re-run) rather
            # than left for the reaper to hand out again and again.
            log.exception(
                "episode %d of scenario %s of run %s crashed the task", episode, scenario_id, run_id
            )
            outcome = _our_failure(job, type(exc).__name__, traceback.format_exc())
    record_key = _record_key(job, outcome)
    with db.session() as session:
        last = evaluation.record_scenario(
            session, job, me, outcome, _log_tail(job, outcome), record_key
        )
    if last:
        _queue().aggregate(run_id)


@arena_task(TASK_AGGREGATE, time_limit=BOOKKEEPING_TIME_LIMIT_S)
def aggregate_run(*, run_id: int) -> None:
    with get_database().session() as session:
        evaluation.finish_run(session, _store(), run_id)


def _training_output(claim: training.TrainingClaim) -> Path:
    return _scratch() / "training" / str(claim.training_id) / f"claim-{claim.claim}"


def _train(claim: training.TrainingClaim, worker: str):
    """Run the submission's train.py; its progress renews the claim's lease, and a lost claim
    or a stopping worker ends it (TrainingStopped)."""
    from evaluator.runner import new_run_key
    from evaluator.training import train

    settings = get_settings()
    if settings.train_dataset_dir is None:
        raise DatasetError("the service has no training dataset (ARENA_TRAIN_DATASET_DIR)")
    output = _training_output(claim)
    shutil.rmtree(output.parent, ignore_errors=True)  # an earlier claim's leftovers on this worker

    def progress(elapsed_s: float, log_text: str) -> bool:
        if _shutting_down.is_set():
            return False
        try:
            with get_database().session() as session:
                return training.heartbeat(
                    session, settings, claim, worker, elapsed_s, _tail(log_text)
                )
        except SQLAlchemyError as exc:
            log.warning("training heartbeat of %s failed: %s", claim.training_id, exc)
            return True

    return train(
        _prepared(claim.upload_key),
        settings.train_dataset_dir,
        output,
        kind=_sandbox_kind(),
        labels={"arena.training": f"t{claim.training_id}c{claim.claim}-{new_run_key()}"},
        settings=settings,
        on_progress=progress,
        progress_every_s=min(max(settings.lease_seconds / 3, 0.5), 5.0),
    )


def _store_model(claim: training.TrainingClaim) -> tuple[str, str, int]:
    """Pack the trained output into the artifact store: (key, sha256, size [bytes])."""
    from evaluator.training import MODEL_ARCHIVE, pack_model

    output = _training_output(claim)
    archive = output.parent / MODEL_ARCHIVE
    sha256 = pack_model(output, archive)
    size = archive.stat().st_size
    key = f"training/{claim.training_id}/claim-{claim.claim}/{MODEL_ARCHIVE}"
    _store().put(key, archive)
    shutil.rmtree(output.parent, ignore_errors=True)
    return key, sha256, size


def _training_failed(
    claim: training.TrainingClaim, worker: str, failure: str, error: str, *, ours: bool
) -> None:
    with get_database().session() as session:
        training.record_failed(session, claim, worker, failure=failure, error=error, ours=ours)


def _hand_back_training(claim: training.TrainingClaim, worker: str) -> None:
    """This worker is stopping: release the training and send it again for another worker."""
    with get_database().session() as session:
        released = training.release(session, claim, worker)
    if released:
        _queue().train(claim.training_id)
        log.warning("handed training %s back", claim.training_id)


def _hand_back(job: evaluation.ScenarioJob, worker: str) -> None:
    """This worker is stopping: the episode was cut short on purpose, so its outcome is not
    the agent's. Release the claim and send the scenario again for another worker."""
    with get_database().session() as session:
        released = evaluation.release_claim(session, job, worker)
    if released:
        _queue().run_scenario(job.run_id, job.key)
        log.warning("handed %s of run %s back", job.key.name, job.run_id)


def _our_failure(job: evaluation.ScenarioJob, reason: str, error: str) -> ScenarioOutcome:
    """A scenario that could not be evaluated through no fault of the submission."""
    return ScenarioOutcome.ours(
        job.scenario_id,
        f"{reason}: {error} (claim {job.attempt})",
        attempts=job.attempt,
        episode=job.episode,
    )


def _simulate(job: evaluation.ScenarioJob, run_key: str) -> ScenarioOutcome:
    import dataclasses

    from evaluator.runner import run_scenario as run_one

    # This worker's own scratch folder, one per claim: an episode whose claim was superseded
    # never touches the live one's files.
    records = _scratch() / "records" / str(job.run_id) / f"claim-{job.attempt}"
    submission = _prepared(job.upload_key)
    if job.model_key is not None:
        submission = dataclasses.replace(submission, model_dir=_model(job.model_key))
    return run_one(
        submission,
        Path(job.scenario_dir),
        records,
        sandbox=_sandbox_kind(),
        run_key=run_key,
        episode=job.episode,
    )


def _record_key(job: evaluation.ScenarioJob, outcome: ScenarioOutcome) -> str | None:
    """Put the episode record in the artifact store, where any worker can score it."""
    if outcome.record_path is None:
        return None
    key = f"runs/{job.run_id}/claim-{job.attempt}/{job.key.name}.npz"
    _store().put(key, outcome.record_path)
    outcome.record_path.unlink(missing_ok=True)
    return key


def _scratch() -> Path:
    """Files of this worker process alone (no ':' in the name: Docker's volume syntax would
    split a path there). Under the data dir, not a private temporary folder: the sandbox user
    must be able to enter a prepared submission."""
    return get_settings().resolved_data_dir / "scratch" / f"{socket.gethostname()}-{os.getpid()}"


@lru_cache(maxsize=1)
def _store() -> ArtifactStore:
    return artifact_store(get_settings(), get_database())


def _log_tail(job: evaluation.ScenarioJob, outcome: ScenarioOutcome) -> str:
    """The tail of the scenario's log the team may see: without the hidden scenario's id."""
    return _tail(outcome.log.replace(job.scenario_id, "<scenario>"))


def _tail(text: str) -> str:
    tail_bytes = get_settings().agent_log_tail_bytes
    return text.encode()[-tail_bytes:].decode("utf-8", "replace")


_prepare_lock = threading.Lock()


def _prepared(upload_key: str):
    """One preparation per submission and worker process, even with several threads asking."""
    with _prepare_lock:
        return _prepare(upload_key)


@lru_cache(maxsize=4)
def _prepare(upload_key: str):
    """The submission ready to run, prepared once per worker process from the zip in the
    artifact store: a worker on another machine needs nothing but the database and broker. The
    intake runs in the sandbox again (its requirements come from the cache when this machine
    validated it): nothing of the participant's is inflated or compiled on this host."""
    from evaluator.validation import validate

    folder = _scratch() / "submissions" / Path(upload_key).parent.name
    zip_path = _store().fetch(upload_key, folder / "upload.zip")
    return validate(zip_path, folder / "prepared", get_settings(), kind=_sandbox_kind())


def _model(model_key: str) -> Path:
    """The trained output, unpacked once per worker process (several threads may ask)."""
    with _prepare_lock:
        return _unpacked_model(model_key)


@lru_cache(maxsize=4)
def _unpacked_model(model_key: str) -> Path:
    import hashlib

    from evaluator.training import unpack_model

    folder = _scratch() / "models" / hashlib.sha256(model_key.encode()).hexdigest()[:16]
    archive = _store().fetch(model_key, folder / "model.tar.gz")
    return unpack_model(archive, folder / "model")


@lru_cache(maxsize=1)
def _sandbox_kind():
    from evaluator import sandbox

    return sandbox.check_service_kind(settings=get_settings())


def _run_key(job: evaluation.ScenarioJob) -> str:
    # Per run, scenario claim and a random part: two submissions of the same zip (or two claims
    # of one scenario) never share sandbox labels, and nothing in it names the scenario.
    from evaluator.runner import new_run_key

    return f"r{job.run_id}a{job.attempt}-{new_run_key()}"


def _sandbox_labels(run_key: str) -> dict[str, str]:
    # The labels every attempt of the runner's sandboxes carries (evaluator.runner.scenario).
    from evaluator.runner import sandbox_labels

    return sandbox_labels(run_key)


@contextmanager
def _heartbeat(job: evaluation.ScenarioJob, worker: str, labels: dict[str, str]):
    """Renew the claim's lease while the scenario runs; when the claim is lost (the run was
    cancelled, or the scenario was handed to another worker), kill the scenario's sandbox: the
    runner then returns, and its result is refused by the fence."""
    settings = get_settings()
    stop = threading.Event()
    handed_back = threading.Event()
    interval = max(settings.lease_seconds / 3, 0.5)

    def beat() -> None:
        next_beat = time.monotonic() + interval
        while not stop.wait(0.2):
            if _shutting_down.is_set():
                from evaluator import sandbox

                # Until the runner returns: an agent still starting up when the first look
                # came, or a simulator retry, must not outlive the worker either.
                handed_back.set()
                sandbox.cleanup(labels)
                continue
            if time.monotonic() < next_beat:
                continue
            next_beat += interval
            try:
                with get_database().session() as session:
                    active = evaluation.heartbeat(session, settings, job, worker)
            except SQLAlchemyError as exc:
                log.warning("lease heartbeat of run %s failed: %s", job.run_id, exc)
                continue
            if not active:
                from evaluator import sandbox

                sandbox.cleanup(labels)
                return

    name = f"lease-{job.run_id}-{job.key.name}"
    thread = threading.Thread(target=beat, name=name, daemon=True)
    thread.start()
    try:
        yield handed_back
    finally:
        stop.set()
        thread.join()


def reap_once() -> evaluation.Reaped:
    """Re-send work whose lease expired (see :func:`server.services.evaluation.reap`)."""
    queue = _queue()
    try:
        queue_empty = queue.depth() == 0
    except BROKER_ERRORS as exc:
        log.warning("reaper cannot read the queue: %s", exc)
        return evaluation.Reaped()
    with get_database().session() as session:
        reaped = evaluation.reap(session, get_settings(), queue_empty=queue_empty)
    for plan in reaped.plans:
        queue.send(plan)
    for submission_id in reaped.submission_ids:
        queue.evaluate(submission_id)
    with get_database().session() as session:
        trainings = training.reap(session, get_settings(), queue_empty=queue_empty)
    for training_id in trainings:
        queue.train(training_id)
    if queue_empty:
        with get_database().read_session() as session:
            for submission_id in validation.stale(session, get_settings()):
                queue.validate(submission_id)
    if reaped.plans or reaped.submission_ids or trainings:
        log.warning(
            "reaper re-sent %d run(s), %d submission(s) and %d training(s)",
            len(reaped.plans),
            len(reaped.submission_ids),
            len(trainings),
        )
    return reaped


_reaper_stop = threading.Event()
# Set when the worker begins a warm shutdown (SIGTERM): running scenarios are handed back.
_shutting_down = threading.Event()


@worker_shutting_down.connect
def _hand_back_running_scenarios(**_: Any) -> None:
    _shutting_down.set()


@worker_ready.connect
def _start_reaper(**_: Any) -> None:
    interval = get_settings().reaper_interval_s

    def loop() -> None:
        from evaluator.sandbox.warm_pool import warm_agents

        while not _reaper_stop.wait(interval):
            try:
                reap_once()
                warm_agents().close_idle(get_settings().warm_agent_idle_s)
            except Exception:  # a bad round must not end the loop; logged with traceback
                log.exception("reaper round failed")

    threading.Thread(target=loop, name="arena-reaper", daemon=True).start()


@worker_shutdown.connect
def _stop_reaper(**_: Any) -> None:
    _reaper_stop.set()


@worker_shutdown.connect
def _remove_scratch(**_: Any) -> None:
    """This process's scratch (prepared submissions, records, models) ends with it."""
    from submissions.intake.archive import remove_tree

    remove_tree(_scratch())


@worker_ready.connect
def _remove_orphan_scratch(**_: Any) -> None:
    """Scratch of this host's worker processes that died without cleaning up."""
    from submissions.intake.archive import remove_tree

    host = socket.gethostname()
    for folder in (get_settings().resolved_data_dir / "scratch").glob(f"{host}-*"):
        pid = folder.name.removeprefix(f"{host}-")
        if pid.isdigit() and not Path(f"/proc/{pid}").exists():
            remove_tree(folder)


@worker_shutdown.connect
def _close_warm_agents(**_: Any) -> None:
    """The warm agent sandboxes this worker kept (one per submission it ran and thread, see
    docs/protocol.md) end with it; running scenarios were handed back before."""
    from evaluator.sandbox.warm_pool import warm_agents

    warm_agents().close()


@worker_process_init.connect
def _after_fork(**_: Any) -> None:
    get_database().after_fork()
    _queue.cache_clear()
    _store.cache_clear()
