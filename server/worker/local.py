"""What one worker process keeps for itself: its name, its scratch folder, its clients (queue,
artifact store) and the submissions and trained models it already unpacked.

Everything here is per process and rebuilt after a fork (:func:`clear`): a worker on another
machine needs nothing but the database, the broker and the artifact store.
"""

from __future__ import annotations

import hashlib
import os
import socket
import threading
from functools import lru_cache
from pathlib import Path

from arena.config import get_settings
from evaluator import sandbox
from evaluator.training import unpack_model
from evaluator.validation import validate
from server.core.artifacts import ArtifactStore, artifact_store
from server.core.db import get_database
from server.core.queue import TaskQueue
from submissions.intake import PreparedSubmission


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


def orphan_scratch() -> list[Path]:
    """Scratch folders of this host's worker processes that no longer run."""
    host = socket.gethostname()
    folders = (get_settings().resolved_data_dir / "scratch").glob(f"{host}-*")
    return [
        folder
        for folder in folders
        if (pid := folder.name.removeprefix(f"{host}-")).isdigit()
        and not Path(f"/proc/{pid}").exists()
    ]


def tail(text: str) -> str:
    """The end of a log, as much as the team may see."""
    tail_bytes = get_settings().agent_log_tail_bytes
    return text.encode()[-tail_bytes:].decode("utf-8", "replace")


_unpack_lock = threading.Lock()


def prepared(upload_key: str) -> PreparedSubmission:
    """One preparation per submission and worker process, even with several threads asking."""
    with _unpack_lock:
        return _prepare(upload_key)


@lru_cache(maxsize=4)
def _prepare(upload_key: str) -> PreparedSubmission:
    """The submission ready to run, prepared once per worker process from the zip in the
    artifact store. The intake runs in the sandbox again (its requirements come from the cache
    when this machine validated it): nothing of the participant's is inflated or compiled on
    this host."""
    folder = scratch() / "submissions" / Path(upload_key).parent.name
    zip_path = store().fetch(upload_key, folder / "upload.zip")
    return validate(zip_path, folder / "prepared", get_settings(), kind=sandbox_kind())


def model(model_key: str) -> Path:
    """The trained output, unpacked once per worker process (several threads may ask)."""
    with _unpack_lock:
        return _unpacked_model(model_key)


@lru_cache(maxsize=4)
def _unpacked_model(model_key: str) -> Path:
    folder = scratch() / "models" / hashlib.sha256(model_key.encode()).hexdigest()[:16]
    archive = store().fetch(model_key, folder / "model.tar.gz")
    return unpack_model(archive, folder / "model")


@lru_cache(maxsize=1)
def sandbox_kind() -> sandbox.SandboxKind:
    return sandbox.check_service_kind(settings=get_settings())


def clear() -> None:
    """Forget the clients of the parent process (after a fork)."""
    queue.cache_clear()
    store.cache_clear()
