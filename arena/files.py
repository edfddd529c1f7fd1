"""Files that readers see whole or not at all, however many writers race for them, and the digest
that names a file by its content."""

from __future__ import annotations

import contextlib
import hashlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def replaced_atomically(dest: Path) -> Iterator[Path]:
    """A fresh path beside ``dest`` to write; moved onto ``dest`` when the block ends, removed
    if it raises. Each writer gets its own partial file: two processes filling one cache entry
    (two test workers, two evaluation workers) would otherwise write into, or move away, each
    other's. The last to finish wins, and every version it replaces was whole."""
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    # Named, not mkstemp: the file keeps the umask's permissions (sandboxes read some of these).
    partial = dest.with_name(f".{dest.name}.{os.getpid()}-{secrets.token_hex(4)}.partial")
    try:
        yield partial
        os.replace(partial, dest)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise


def write_atomically(dest: Path, data: bytes | str) -> Path:
    with replaced_atomically(dest) as partial:
        if isinstance(data, str):
            partial.write_text(data)
        else:
            partial.write_bytes(data)
    return Path(dest)


def file_sha256(path: Path) -> str:
    """The hex sha256 of the file's bytes, read a MiB at a time (uploads and models are large)."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as handle:
        while chunk := handle.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()
