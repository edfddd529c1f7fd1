"""A trained output folder as one stored file: a deterministic ``.tar.gz`` with its sha256.

The same folder always packs to the same bytes (sorted entries, no times or owners), so the
sha256 the service stores names the model itself. Only regular files and folders are kept: a
symlink the training left could point anywhere on the worker.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import os
import tarfile
from dataclasses import dataclass
from pathlib import Path

MODEL_ARCHIVE = "model.tar.gz"


@dataclass(frozen=True)
class OutputUsage:
    """What an output folder holds: bytes of its files, entries (files, folders, links) and the
    depth of its deepest entry (1: directly in it). Counting stops past ``max_entries``."""

    bytes: int
    entries: int
    depth: int

    def over(self, max_bytes: int, max_entries: int, max_depth: int) -> str | None:
        """Which cap it is past, said for the team, or None."""
        if self.entries > max_entries:
            return f"more than {max_entries} files and folders"
        if self.depth > max_depth:
            return f"folders nested deeper than {max_depth}"
        if self.bytes > max_bytes:
            return f"{self.bytes} bytes, past its cap of {max_bytes}"
        return None


def output_usage(folder: Path, max_entries: int) -> OutputUsage:
    """Measure ``folder`` without following links; never looks at more than ``max_entries + 1``
    entries, so a training that made millions costs the same as one that made a few."""
    total = entries = deepest = 0
    pending = [(folder, 1)]
    while pending:
        path, depth = pending.pop()
        try:
            listing = os.scandir(path)
        except OSError:  # removed while we looked: training still runs
            continue
        with listing:
            for entry in listing:
                entries += 1
                deepest = max(deepest, depth)
                if entries > max_entries:
                    return OutputUsage(total, entries, deepest)
                try:
                    if entry.is_dir(follow_symlinks=False):
                        pending.append((Path(entry.path), depth + 1))
                    elif entry.is_file(follow_symlinks=False):
                        total += entry.stat(follow_symlinks=False).st_size
                except OSError:
                    continue
    return OutputUsage(total, entries, deepest)


def regular_files(folder: Path) -> list[Path]:
    """Every regular file under ``folder`` (symlinks not followed), sorted."""
    found = []
    for root, dirs, files in os.walk(folder):
        dirs.sort()
        for name in sorted(files):
            path = Path(root) / name
            if path.is_file() and not path.is_symlink():
                found.append(path)
    return found


def folder_digest(folder: Path) -> str:
    """sha256 of the folder's files (relative paths and contents): a local model's identity."""
    digest = hashlib.sha256()
    for path in regular_files(folder):
        digest.update(str(path.relative_to(folder)).encode() + b"\0")
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()


def pack_model(folder: Path, archive: Path) -> str:
    """Write ``folder``'s regular files to ``archive``; returns the archive's sha256."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for path in regular_files(folder):
            info = tarfile.TarInfo(str(path.relative_to(folder)))
            info.mode = 0o644
            # The size of the file opened, not of the path: a checkpoint snapshot packs a folder
            # whose files training may replace meanwhile (evaluator/training/checkpoint.py).
            with path.open("rb") as handle:
                info.size = os.fstat(handle.fileno()).st_size
                tar.addfile(info, handle)
    archive.parent.mkdir(parents=True, exist_ok=True)
    # No name and no time in the gzip header: the same files give the same bytes.
    with (
        archive.open("wb") as raw,
        gzip.GzipFile(filename="", fileobj=raw, mode="wb", mtime=0) as zipped,
    ):
        zipped.write(buffer.getvalue())
    return hashlib.sha256(archive.read_bytes()).hexdigest()


def unpack_model(archive: Path, dest: Path) -> Path:
    """Extract a packed model into ``dest`` (readable by the sandbox user); returns ``dest``."""
    dest.mkdir(parents=True, exist_ok=True)
    with tarfile.open(archive, mode="r:gz") as tar:
        tar.extractall(dest, filter="data")
    for root, _, files in os.walk(dest):
        os.chmod(root, 0o755)
        for name in files:
            os.chmod(Path(root) / name, 0o644)
    return dest
