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
from submissions.intake.archive import remove_tree


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
# What this process unpacked, by key: kept while the submission is in work, deleted (folder and
# all) once it is not (forget_finished), so a long-running worker's scratch does not grow.
_prepared: dict[str, PreparedSubmission] = {}
_models: dict[str, Path] = {}


def prepared(upload_key: str) -> PreparedSubmission:
    """One preparation per submission and worker process, even with several threads asking."""
    with _unpack_lock:
        if upload_key not in _prepared:
            _prepared[upload_key] = _prepare(upload_key)
        return _prepared[upload_key]


def _prepare(upload_key: str) -> PreparedSubmission:
    """The submission ready to run, prepared once per worker process from the zip in the
    artifact store. The intake runs in the sandbox again (its requirements come from the cache
    when this machine validated it): nothing of the participant's is inflated or compiled on
    this host."""
    folder = _submission_folder(upload_key)
    zip_path = store().fetch(upload_key, folder / "upload.zip")
    return validate(zip_path, folder / "prepared", get_settings(), kind=sandbox_kind())


def model(model_key: str) -> Path:
    """The trained output, unpacked once per worker process (several threads may ask)."""
    with _unpack_lock:
        if model_key not in _models:
            folder = _model_folder(model_key)
            archive = store().fetch(model_key, folder / "model.tar.gz")
            _models[model_key] = unpack_model(archive, folder / "model")
        return _models[model_key]


def _submission_folder(upload_key: str) -> Path:
    return scratch() / "submissions" / Path(upload_key).parent.name


def _model_folder(model_key: str) -> Path:
    return scratch() / "models" / hashlib.sha256(model_key.encode()).hexdigest()[:16]


def forget_finished(upload_keys: set[str], model_keys: set[str]) -> int:
    """Delete what this process unpacked for submissions no longer in work (their runs ended):
    only ``upload_keys`` and ``model_keys`` are kept. How many folders went."""
    with _unpack_lock:
        gone = [(key, _submission_folder(key)) for key in _prepared if key not in upload_keys]
        gone_models = [(key, _model_folder(key)) for key in _models if key not in model_keys]
        for key, folder in gone:
            del _prepared[key]
            remove_tree(folder)
        for key, folder in gone_models:
            del _models[key]
            remove_tree(folder)
    return len(gone) + len(gone_models)


@lru_cache(maxsize=1)
def sandbox_kind() -> sandbox.SandboxKind:
    return sandbox.check_service_kind(settings=get_settings())


def clear() -> None:
    """Forget the clients of the parent process (after a fork)."""
    queue.cache_clear()
    store.cache_clear()
