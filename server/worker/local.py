"""What one worker process keeps for itself: its name, its scratch folder, its clients (queue,
artifact store) and the submissions and trained models it already unpacked.

Everything here is per process and rebuilt after a fork (:func:`clear`): a worker on another
machine needs nothing but the database, the broker and the artifact store.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import pickle
import shutil
import socket
import threading
import uuid
from functools import lru_cache
from pathlib import Path

from arena.config import get_settings
from evaluator import sandbox
from evaluator.training import unpack_model
from server.core.artifacts import ArtifactStore, artifact_store
from server.core.db import get_database
from server.core.queue import TaskQueue
from server.services.storable import storable_text
from submissions.intake import PreparedSubmission, prepare_submission


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


@lru_cache(maxsize=1)
def queue() -> TaskQueue:
    return TaskQueue(get_settings())


@lru_cache(maxsize=1)
def store() -> ArtifactStore:
    return artifact_store(get_settings(), get_database())


def scratch() -> Path:
    """Files of this worker process alone (no ':' in the name: Docker's volume syntax would
    split a path there). Under the data dir, not a private temporary folder: the sandbox user
    must be able to enter a prepared submission."""
    return get_settings().resolved_data_dir / "scratch" / f"{socket.gethostname()}-{os.getpid()}"


def tail(text: str) -> str:
    """The end of a log, as much as the team may see, storable whatever it holds (lone
    surrogates, NULs: a strict encode here crashed the task, an uncharged ``worker_lost``)."""
    tail_bytes = get_settings().agent_log_tail_bytes
    cut = text.encode("utf-8", "surrogatepass")[-tail_bytes:].decode("utf-8", "replace")
    return storable_text(cut)


_unpack_lock = threading.Lock()
# Beside each prepared submission: its PreparedSubmission, pickled.
PREPARED_DESCRIPTION = "prepared.pickle"


def prepared(upload_key: str) -> PreparedSubmission:
    """One preparation per submission and worker process, even with several threads asking."""
    with _unpack_lock:
        return _prepare(upload_key)


@lru_cache(maxsize=4)
def _prepare(upload_key: str) -> PreparedSubmission:
    """The submission ready to run, prepared once per worker process from the zip in the
    artifact store.

    Into a folder named after the zip's digest, made whole in a staging folder then renamed,
    and never changed again: a warm agent binds it (its pool is keyed by that digest), so one
    prepared again after this cache dropped it finds the same folder (the description beside it)
    instead of deleting files under a live sandbox."""
    root = scratch() / "submissions"
    staging = root / f"staging-{uuid.uuid4().hex}"
    try:
        zip_path = store().fetch(upload_key, staging / "upload.zip")
        final = root / _file_sha256(zip_path)
        described = final / PREPARED_DESCRIPTION
        if not described.is_file():
            ready = prepare_submission(zip_path, staging / "prepared", get_settings())
            (staging / PREPARED_DESCRIPTION).write_bytes(pickle.dumps(ready))
            try:
                staging.rename(final)
            except OSError:  # another thread of this process got there first: same content
                if not described.is_file():
                    raise
        # Written by this process into its own scratch folder, which no sandbox can write.
        ready = pickle.loads(described.read_bytes())
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return dataclasses.replace(ready, root=final / "prepared")


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        while chunk := file.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def model(model_key: str) -> Path:
    """The trained output, unpacked once per worker process (several threads may ask)."""
    with _unpack_lock:
        return _unpacked_model(model_key)


@lru_cache(maxsize=4)
def _unpacked_model(model_key: str) -> Path:
    """Unpacked once into a folder of its own, never changed again (as :func:`_prepare`)."""
    folder = scratch() / "models" / hashlib.sha256(model_key.encode()).hexdigest()[:16]
    if (folder / "model").is_dir():
        return folder / "model"
    staging = folder.with_name(f"staging-{uuid.uuid4().hex}")
    try:
        archive = store().fetch(model_key, staging / "model.tar.gz")
        unpack_model(archive, staging / "model")
        (staging / "model.tar.gz").unlink()
        staging.rename(folder)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return folder / "model"


@lru_cache(maxsize=1)
def sandbox_kind() -> sandbox.SandboxKind:
    return sandbox.check_service_kind(settings=get_settings())


def clear() -> None:
    """Forget the clients of the parent process (after a fork)."""
    queue.cache_clear()
    store.cache_clear()
