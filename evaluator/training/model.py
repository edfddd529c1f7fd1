"""A trained output folder as one stored file: a deterministic ``.tar.gz`` with its sha256.

The same folder always packs to the same bytes (sorted entries, no times or owners), so the
sha256 the service stores names the model itself. Only regular files and folders are kept: a
symlink the training left could point anywhere on the worker.

The folder is the team's, and a checkpoint packs it while ``train.py`` still writes it: it is
walked by descriptors (each name opened ``O_NOFOLLOW`` relative to its folder's descriptor, never
a path resolved again), so a name swapped for a link between the listing and the opening is
skipped, not followed; hard-linked files are skipped too (a link to a file the team does not
own). The archive is streamed, and its caps are counted in the files' apparent sizes as they are
packed: a sparse file counts what it reads as.
"""

from __future__ import annotations

import gzip
import hashlib
import os
import stat
import tarfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from arena.errors import ArenaError
from arena.files import file_sha256

MODEL_ARCHIVE = "model.tar.gz"
# How a name below the folder is opened: never through a link, never blocking on a fifo.
_OPEN_FLAGS = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC


class PackRefused(ArenaError):
    """The folder is past a cap of the packing, or a file changed size while it was packed."""


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


def pack_model(
    folder: Path,
    archive: Path,
    *,
    max_bytes: int | None = None,
    max_entries: int | None = None,
) -> str:
    """Write ``folder``'s regular files to ``archive`` (streamed: memory stays small whatever
    the folder holds); returns the archive's sha256. Past ``max_bytes`` of files (apparent
    sizes) or ``max_entries`` files and folders: :class:`PackRefused`, nothing left."""
    archive.parent.mkdir(parents=True, exist_ok=True)
    try:
        # No name and no time in the gzip header: the same files give the same bytes.
        with (
            archive.open("wb") as raw,
            gzip.GzipFile(filename="", fileobj=raw, mode="wb", mtime=0) as zipped,
            tarfile.open(fileobj=zipped, mode="w", format=tarfile.PAX_FORMAT) as tar,
        ):
            packed = 0
            for name, handle in _files_below(folder, max_entries):
                with handle:
                    info = tarfile.TarInfo(name)
                    info.mode = 0o644
                    # The size of the file opened, not of the path: training may replace it.
                    info.size = os.fstat(handle.fileno()).st_size
                    packed += info.size
                    if max_bytes is not None and packed > max_bytes:
                        raise PackRefused(f"the folder holds more than {max_bytes} bytes")
                    try:
                        tar.addfile(info, handle)
                    except OSError as error:  # shorter than its size said: changed meanwhile
                        raise PackRefused(f"{name} changed while it was packed") from error
    except BaseException:
        archive.unlink(missing_ok=True)
        raise
    return file_sha256(archive)


def _files_below(folder: Path, max_entries: int | None) -> Iterator[tuple[str, object]]:
    """(relative name, open binary file) of every regular file below ``folder``, sorted, each
    reached from its folder's descriptor without following a link; the caller closes each."""
    root = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    entries = 0
    pending: list[tuple[int, str]] = [(root, "")]
    try:
        while pending:
            directory, prefix = pending.pop()
            subfolders: list[tuple[int, str]] = []
            try:
                for name in sorted(os.listdir(directory)):
                    entries += 1
                    if max_entries is not None and entries > max_entries:
                        raise PackRefused(f"the folder holds more than {max_entries} entries")
                    try:
                        fd = os.open(name, _OPEN_FLAGS, dir_fd=directory)
                    except OSError:  # a link (ELOOP), a socket, or gone meanwhile: not packed
                        continue
                    info = os.fstat(fd)
                    if stat.S_ISDIR(info.st_mode):
                        subfolders.append((fd, f"{prefix}{name}/"))
                    elif stat.S_ISREG(info.st_mode) and info.st_nlink == 1:
                        yield f"{prefix}{name}", os.fdopen(fd, "rb")
                    else:
                        os.close(fd)
            finally:
                os.close(directory)
                # Depth first, in name order: the same folder gives the same archive.
                pending.extend(reversed(subfolders))
    finally:
        for directory, _ in pending:
            os.close(directory)


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
