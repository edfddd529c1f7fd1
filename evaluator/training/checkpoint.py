"""Snapshots of a training's output folder while ``train.py`` runs, and their restoration.

A training re-sent after its worker died starts with ``ARENA_MODEL_DIR`` holding the last
snapshot (docs/dataset.md): :class:`CheckpointWatch` packs the folder at most every
``interval_s``, only when it changed and only up to ``max_bytes``; :func:`restore` unpacks a
snapshot into a fresh output folder, writable by the sandbox user. The folder is packed while
``train.py`` may be writing it: a file that changes under the packing makes that round fail
(:class:`SnapshotFailed`) and the next one try again; ``train.py`` writes its checkpoints
atomically (a temporary name, then a rename) so every round sees whole files.
"""

from __future__ import annotations

import os
import tarfile
import time
from pathlib import Path

from arena.errors import ArenaError
from evaluator.sandbox.batch_folders import SANDBOX_UID
from evaluator.training.model import (
    PackRefused,
    output_usage,
    pack_model,
    regular_files,
    unpack_model,
)


class SnapshotFailed(ArenaError):
    """The folder changed while it was packed, or is past the snapshot cap; nothing stored."""


def folder_signature(folder: Path) -> tuple[tuple[str, int, int], ...]:
    """(path, size, mtime) of every regular file: what tells a changed folder, without reading
    it."""
    signature = []
    for path in regular_files(folder):
        try:
            stat = path.lstat()
        except FileNotFoundError:  # removed while we looked
            continue
        signature.append((str(path.relative_to(folder)), stat.st_size, stat.st_mtime_ns))
    return tuple(signature)


class CheckpointWatch:
    """Decides when the output folder is worth a new snapshot, and takes it."""

    def __init__(
        self, output: Path, *, interval_s: float, max_bytes: int, max_entries: int
    ) -> None:
        self.output = Path(output)
        self.interval_s = interval_s
        self.max_bytes = max_bytes
        self.max_entries = max_entries
        self._last_signature: tuple = ()
        self._last_try = time.monotonic()

    def due(self) -> bool:
        return self.interval_s > 0 and time.monotonic() - self._last_try >= self.interval_s

    def snapshot(self, archive: Path) -> bool:
        """Pack the folder into ``archive`` if it changed since the last snapshot; True when a
        new archive was written. Raises :class:`SnapshotFailed` (the next round tries again)."""
        self._last_try = time.monotonic()
        # Measured first, by a walk bounded in entries: the signature below reads every file.
        usage = output_usage(self.output, self.max_entries)
        if usage.entries > self.max_entries:
            raise SnapshotFailed(
                f"the output folder holds more than {self.max_entries} entries: not saved"
            )
        if usage.bytes > self.max_bytes:
            raise SnapshotFailed(
                f"the output folder holds {usage.bytes} bytes, past the checkpoint cap of "
                f"{self.max_bytes}: not saved"
            )
        signature = folder_signature(self.output)
        if not signature or signature == self._last_signature:
            return False
        try:
            # Capped again while packing: the folder may grow between the measure and the pack.
            pack_model(self.output, archive, max_bytes=self.max_bytes, max_entries=self.max_entries)
        except PackRefused as error:
            raise SnapshotFailed(f"not saved: {error}") from error
        except (OSError, tarfile.TarError) as error:
            archive.unlink(missing_ok=True)
            raise SnapshotFailed(
                f"the output folder changed while it was saved: {error}"
            ) from error
        if folder_signature(self.output) != signature:
            archive.unlink(missing_ok=True)
            raise SnapshotFailed("the output folder changed while it was saved")
        self._last_signature = signature
        return True


def restore(archive: Path, output: Path) -> Path:
    """Unpack a snapshot into the empty folder ``output``, writable by the sandbox user (who
    overwrites and removes its checkpoints). Returns ``output``."""
    unpack_model(archive, output)
    for root, _, files in os.walk(output):
        for path in [Path(root), *(Path(root) / name for name in files)]:
            hand_to_sandbox_user(path)
    return output


def hand_to_sandbox_user(path: Path) -> None:
    """Make ``path`` writable by the sandbox user: its owner when we are root, else by all."""
    if os.geteuid() == 0:
        os.chown(path, SANDBOX_UID, SANDBOX_UID)
    else:
        path.chmod(0o777 if path.is_dir() else 0o666)
