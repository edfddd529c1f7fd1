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
from pathlib import Path

MODEL_ARCHIVE = "model.tar.gz"


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


def output_bytes(folder: Path) -> int:
    """The size of the files under ``folder`` [bytes]: what storing them would take (a sparse
    file counts in full)."""
    total = 0
    for root, _, files in os.walk(folder):
        for name in files:
            try:
                stat = (Path(root) / name).lstat()
            except FileNotFoundError:  # removed while we looked: training still runs
                continue
            total += stat.st_size
    return total


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
