"""The artifact store: uploads, episode records (and, with Track 2, trained models) by key.

Workers share nothing but the broker and the database: whatever one process writes and another
reads goes through here. Two backends: a folder (the embedded default: the data folder itself)
and the database (production with several worker machines: nothing else to run or share).
Keys are relative POSIX paths such as ``submissions/<id>/upload.zip``.
"""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path, PurePosixPath
from typing import Protocol

from sqlalchemy import delete, or_, select

from arena.config import ArtifactBackend, StorageSettings
from arena.errors import ArenaError
from arena.files import file_sha256, replaced_atomically, write_atomically
from server.core.db import Database
from server.models import Artifact, utcnow


class MissingArtifact(ArenaError, LookupError):
    """No artifact under that key."""


class ArtifactStore(Protocol):
    def put(self, key: str, source: Path) -> str:
        """Store the file ``source`` under ``key`` (replacing it); returns its sha256."""

    def fetch(self, key: str, dest: Path) -> Path:
        """Write the artifact to ``dest`` (atomically) and return ``dest``."""

    def read(self, key: str) -> bytes: ...

    def exists(self, key: str) -> bool: ...

    def delete_prefix(self, prefix: str) -> int:
        """Remove the artifact ``prefix`` and every one below it (``prefix/...``); returns how
        many."""


def checked_key(key: str) -> str:
    path = PurePosixPath(key)
    if path.is_absolute() or ".." in path.parts or not path.parts:
        raise ValueError(f"not an artifact key: {key!r}")
    return path.as_posix()


class FolderStore:
    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    def _path(self, key: str) -> Path:
        return self.root / checked_key(key)

    def put(self, key: str, source: Path) -> str:
        dest = self._path(key)
        if Path(source).resolve() != dest.resolve():
            with replaced_atomically(dest) as partial:
                shutil.copyfile(source, partial)
        return file_sha256(dest)

    def fetch(self, key: str, dest: Path) -> Path:
        return write_atomically(Path(dest), self.read(key))

    def read(self, key: str) -> bytes:
        try:
            return self._path(key).read_bytes()
        except FileNotFoundError:
            raise MissingArtifact(key) from None

    def exists(self, key: str) -> bool:
        return self._path(key).is_file()

    def delete_prefix(self, prefix: str) -> int:
        target = self._path(prefix)
        if target.is_file():
            target.unlink()
            return 1
        if not target.is_dir():
            return 0
        count = sum(1 for p in target.rglob("*") if p.is_file())
        shutil.rmtree(target, ignore_errors=True)
        return count


class DatabaseStore:
    """Artifacts as rows of the ``artifacts`` table: the database every worker already has."""

    def __init__(self, db: Database) -> None:
        self.db = db

    def put(self, key: str, source: Path) -> str:
        data = Path(source).read_bytes()
        digest = hashlib.sha256(data).hexdigest()
        key = checked_key(key)
        with self.db.session() as session:
            session.execute(delete(Artifact).where(Artifact.key == key))
            session.add(
                Artifact(key=key, sha256=digest, size=len(data), data=data, created_at=utcnow())
            )
        return digest

    def fetch(self, key: str, dest: Path) -> Path:
        return write_atomically(Path(dest), self.read(key))

    def read(self, key: str) -> bytes:
        with self.db.read_session() as session:
            data = session.scalar(select(Artifact.data).where(Artifact.key == checked_key(key)))
        if data is None:
            raise MissingArtifact(key)
        return bytes(data)

    def exists(self, key: str) -> bool:
        with self.db.read_session() as session:
            found = session.scalar(select(Artifact.key).where(Artifact.key == checked_key(key)))
        return found is not None

    def delete_prefix(self, prefix: str) -> int:
        prefix = checked_key(prefix)
        with self.db.session() as session:
            removed = session.execute(
                delete(Artifact).where(
                    or_(
                        Artifact.key == prefix,
                        Artifact.key.startswith(prefix + "/", autoescape=True),
                    )
                )
            )
        return removed.rowcount


def artifact_store(storage: StorageSettings, db: Database) -> ArtifactStore:
    if storage.artifact_store is ArtifactBackend.database:
        return DatabaseStore(db)
    return FolderStore(storage.resolved_data_dir)
