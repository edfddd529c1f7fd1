"""What one worker process keeps for itself: its name, its scratch folder, its clients (database,
queue, artifact store) and the submissions and trained models it already unpacked. With the task
bodies (:mod:`server.worker.tasks`) this is the worker's composition root: the settings are read
here and handed down to the job kinds and the layers below.

Everything here is per process and rebuilt after a fork (:func:`clear`): a worker on another
machine needs nothing but the database, the broker and the artifact store.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import pickle
import socket
import threading
import uuid
from functools import lru_cache
from pathlib import Path

from arena.config import get_settings
from arena.files import file_sha256
from arena.neutralise.storable import storable_text
from evaluator import sandbox
from evaluator.sandbox.warm_pool import warm_agents
from evaluator.training import unpack_model
from evaluator.validation import validate
from server.core.artifacts import ArtifactStore, artifact_store
from server.core.db import Database
from server.core.queue import TaskQueue
from server.jobs.kind import Worker
from sim.episode_workers import episode_workers
from submissions.intake import PreparedSubmission
from submissions.intake.archive import remove_tree


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


@lru_cache(maxsize=1)
def database() -> Database:
    return Database(get_settings().storage.resolved_database_url)


@lru_cache(maxsize=1)
def queue() -> TaskQueue:
    return TaskQueue(get_settings())


def worker() -> Worker:
    """This process as the job engine sees it (after a fork: the child's name and clients)."""
    return Worker(worker_name(), database(), queue())


@lru_cache(maxsize=1)
def store() -> ArtifactStore:
    return artifact_store(get_settings().storage, database())


def scratch() -> Path:
    """Files of this worker process alone (no ':' in the name: Docker's volume syntax would
    split a path there). Under the data dir, not a private temporary folder: the sandbox user
    must be able to enter a prepared submission."""
    return (
        get_settings().storage.resolved_data_dir
        / "scratch"
        / f"{socket.gethostname()}-{os.getpid()}"
    )


def orphan_scratch() -> list[Path]:
    """Scratch folders of this host's worker processes that no longer run."""
    host = socket.gethostname()
    folders = (get_settings().storage.resolved_data_dir / "scratch").glob(f"{host}-*")
    return [
        folder
        for folder in folders
        if (pid := folder.name.removeprefix(f"{host}-")).isdigit()
        and not Path(f"/proc/{pid}").exists()
    ]


def tail(text: str) -> str:
    """The end of a log, as much as the team may see, storable whatever it holds (lone
    surrogates, NULs: a strict encode here crashed the task, an uncharged ``worker_lost``)."""
    tail_bytes = get_settings().sandbox.agent_log_tail_bytes
    cut = text.encode("utf-8", "surrogatepass")[-tail_bytes:].decode("utf-8", "replace")
    return storable_text(cut)


_unpack_lock = threading.Lock()
# Beside each prepared submission: its PreparedSubmission, pickled.
PREPARED_DESCRIPTION = "prepared.pickle"
# What this process unpacked, by key: kept while the submission is in work, deleted (folder and
# all) once it is not (forget_finished), so a long-running worker's scratch does not grow.
_prepared: dict[str, PreparedSubmission] = {}
_models: dict[str, Path] = {}


def prepared(upload_key: str) -> PreparedSubmission:
    """One preparation per submission and worker process, even with several threads asking;
    prepared again if its folder is no longer whole (it never is half: :func:`_discard`)."""
    with _unpack_lock:
        ready = _prepared.get(upload_key)
        if ready is None or not (ready.root.parent / PREPARED_DESCRIPTION).is_file():
            _prepared[upload_key] = ready = _prepare(upload_key)
        return ready


def _prepare(upload_key: str) -> PreparedSubmission:
    """The submission ready to run, prepared once per worker process from the zip in the
    artifact store. The intake runs in the sandbox again (its requirements come from the cache
    when this machine validated it): nothing of the participant's is inflated or compiled on
    this host.

    Into a folder named after the zip's digest, made whole in a staging folder then renamed,
    and never changed while it is in work: a warm agent binds it (its pool is keyed by that
    digest), and two uploads of the same zip share it. The folder is whole when its description
    is there; one without (a removal cut short by a restart before removals were atomic) is
    replaced, never renamed onto (``ENOTEMPTY``) nor run."""
    root = scratch() / "submissions"
    staging = root / f"staging-{uuid.uuid4().hex}"
    try:
        zip_path = store().fetch(upload_key, staging / "upload.zip")
        final = root / file_sha256(zip_path)
        described = final / PREPARED_DESCRIPTION
        if not described.is_file():
            settings = get_settings()
            ready = validate(
                zip_path,
                staging / "prepared",
                settings.intake,
                settings.sandbox,
                settings.storage.resolved_data_dir,
                kind=sandbox_kind(),
            )
            (staging / PREPARED_DESCRIPTION).write_bytes(pickle.dumps(ready))
            _discard(final)
            staging.rename(final)
        # Written by this process into its own scratch folder, which no sandbox can write.
        ready = pickle.loads(described.read_bytes())
    finally:
        remove_tree(staging)
    return dataclasses.replace(ready, root=final / "prepared")


def _discard(folder: Path) -> None:
    """Remove ``folder`` so that nobody ever finds it half removed: renamed aside (atomic),
    then deleted. A process killed in between leaves a ``trash-`` folder, never a broken one."""
    trash = folder.with_name(f"trash-{uuid.uuid4().hex}")
    try:
        folder.rename(trash)
    except FileNotFoundError:
        return
    remove_tree(trash)


def model(model_key: str) -> Path:
    """The trained output, unpacked once per worker process (several threads may ask)."""
    with _unpack_lock:
        if model_key not in _models:
            _models[model_key] = _unpacked_model(model_key)
        return _models[model_key]


def _unpacked_model(model_key: str) -> Path:
    """Unpacked once into a folder of its own, never changed while it is in work."""
    folder = _model_folder(model_key)
    if (folder / "model").is_dir():
        return folder / "model"
    staging = folder.with_name(f"staging-{uuid.uuid4().hex}")
    try:
        archive = store().fetch(model_key, staging / "model.tar.gz")
        unpack_model(archive, staging / "model")
        (staging / "model.tar.gz").unlink()
        _discard(folder)
        staging.rename(folder)
    finally:
        remove_tree(staging)
    return folder / "model"


def _model_folder(model_key: str) -> Path:
    return scratch() / "models" / hashlib.sha256(model_key.encode()).hexdigest()[:16]


def forget_finished(upload_keys: set[str], model_keys: set[str]) -> int:
    """Delete what this process unpacked for submissions no longer in work (their runs ended):
    only ``upload_keys`` and ``model_keys`` are kept. How many folders went. The idle warm
    agents bound to a folder close first; a folder another upload in work shares (same zip)
    stays. With nothing of this process left in work, its idle episode processes
    (:mod:`sim.episode_workers`) end too: they hold a simulator's memory each, and would
    otherwise wait out their idle time after the last episode."""
    with _unpack_lock:
        gone = [_prepared.pop(key) for key in list(_prepared) if key not in upload_keys]
        kept = {submission.root.parent for submission in _prepared.values()}
        folders = {s.root.parent: s.sha256 for s in gone if s.root.parent not in kept}
        gone_models = [_models.pop(key) for key in list(_models) if key not in model_keys]
        for folder, sha256 in folders.items():
            warm_agents().close(sha256)
            _discard(folder)
        for model_dir in gone_models:
            warm_agents().close(model_dir=model_dir)
            _discard(model_dir.parent)
        idle = not _prepared and not _models
    if idle:
        episode_workers().close()
    return len(folders) + len(gone_models)


@lru_cache(maxsize=1)
def sandbox_kind() -> sandbox.SandboxKind:
    return sandbox.check_service_kind(None, get_settings().sandbox)


def clear() -> None:
    """Forget the clients of the parent process (after a fork)."""
    queue.cache_clear()
    store.cache_clear()
