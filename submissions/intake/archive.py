"""Checking and extracting a submission zip without trusting a byte of it.

Every entry is checked before anything is written: the archive's size, entry count and total
uncompressed size, each entry's name (no absolute paths, no ``..``), kind (regular files and
folders only: no symlinks, devices, fifos) and compression ratio, and nested archives, whose
contents count against the same limits. Extraction then writes only what was checked, counting
bytes again in case an entry lies about its size.
"""

from __future__ import annotations

import bz2
import io
import lzma
import shutil
import stat
import zipfile
import zlib
from pathlib import Path, PurePosixPath

from arena.config import Settings
from arena.errors import IntakeError

ARCHIVE = "<zip>"
# Ratios are judged only above this size: small files of padding compress absurdly well.
RATIO_FLOOR_BYTES = 1024**2
# A nested archive inside a nested archive inside the submission is as deep as we look.
MAX_NESTING = 2
COPY_CHUNK = 1024**2
STREAM_MAGIC = {
    b"\x1f\x8b": "gzip",
    b"BZh": "bzip2",
    b"\xfd7zXZ\x00": "xz",
}
ZIP_MAGIC = b"PK\x03\x04"
# Linux's limits: a longer name cannot be written, so it is refused before extraction.
MAX_NAME_PART_BYTES = 255
MAX_NAME_BYTES = 1024
# What reading a damaged entry raises: a bad CRC, a truncated or corrupt deflate stream, a
# compression method Python lacks.
CORRUPT_ENTRY_ERRORS = (
    zipfile.BadZipFile,
    zlib.error,
    lzma.LZMAError,
    EOFError,
    NotImplementedError,
)


class Budget:
    """What is left of the entry and byte limits while the archive (and its nested ones) is read."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.entries = settings.max_zip_entries
        self.bytes = settings.max_unzipped_bytes

    def take_entry(self, name: str) -> None:
        self.entries -= 1
        if self.entries < 0:
            raise IntakeError(
                name,
                "max-entries",
                f"more than {self.settings.max_zip_entries} entries (nested archives included)",
            )

    def take_bytes(self, name: str, size: int) -> None:
        self.bytes -= size
        if self.bytes < 0:
            limit = self.settings.max_unzipped_bytes / 1024**2
            raise IntakeError(
                name,
                "max-unzipped-bytes",
                f"more than {limit:g} MiB uncompressed (nested archives included)",
            )


def open_zip(path: Path, settings: Settings) -> zipfile.ZipFile:
    size = path.stat().st_size
    if size == 0:
        raise IntakeError(ARCHIVE, "empty-file", "the upload is an empty file, not a zip")
    if size > settings.max_zip_bytes:
        limit = settings.max_zip_bytes / 1024**2
        raise IntakeError(ARCHIVE, "max-zip-bytes", f"the zip is larger than {limit:g} MiB")
    try:
        return zipfile.ZipFile(path)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError) as error:
        raise IntakeError(
            ARCHIVE, "not-a-zip", f"the upload is not a readable zip ({error})"
        ) from error


def entry_path(info: zipfile.ZipInfo) -> PurePosixPath:
    """The entry's relative path, or an IntakeError for names that could escape the folder."""
    name = info.filename
    if not name or "\0" in name:
        raise IntakeError(repr(name), "bad-name", "an entry has an empty or NUL-containing name")
    if name.startswith(("/", "\\")) or (len(name) > 1 and name[1] == ":"):
        raise IntakeError(name, "absolute-path", "absolute paths are not allowed in the zip")
    parts = PurePosixPath(name.replace("\\", "/")).parts
    if ".." in parts:
        raise IntakeError(name, "zip-slip", "'..' in an entry name would write outside the folder")
    if not parts or parts == (".",):
        raise IntakeError(name, "bad-name", "an entry name points at the folder itself")
    longest = max(len(part.encode()) for part in parts)
    if longest > MAX_NAME_PART_BYTES or len(name.encode()) > MAX_NAME_BYTES:
        raise IntakeError(
            name[:80] + ("..." if len(name) > 80 else ""),
            "name-too-long",
            f"a file or folder name is over {MAX_NAME_PART_BYTES} bytes, or the path over "
            f"{MAX_NAME_BYTES}",
        )
    return PurePosixPath(*parts)


def read_entry(archive: zipfile.ZipFile, info: zipfile.ZipInfo | str, limit: int = -1) -> bytes:
    """An entry's bytes (at most ``limit``); a damaged entry is the zip's fault, named as such."""
    name = info if isinstance(info, str) else info.filename
    try:
        with archive.open(info) as handle:
            return handle.read(limit)
    except CORRUPT_ENTRY_ERRORS as error:
        raise IntakeError(name, "corrupt-entry", f"cannot be read: {error}") from error


UNIX_CREATE_SYSTEM = 3


def check_kind(info: zipfile.ZipInfo) -> None:
    if info.flag_bits & 0x1:
        raise IntakeError(info.filename, "encrypted", "encrypted entries cannot be read")
    # Only Unix-made zips carry a file type in the high attribute bits, and many tools (Python's
    # own ZipFile.writestr among them) write permission bits with no type: that is a plain file.
    if info.create_system != UNIX_CREATE_SYSTEM:
        return
    kind = stat.S_IFMT(info.external_attr >> 16)
    if kind == stat.S_IFLNK:
        raise IntakeError(info.filename, "symlink", "symbolic links are not allowed")
    if kind not in (0, stat.S_IFREG, stat.S_IFDIR):
        raise IntakeError(
            info.filename, "special-file", "device files, fifos and sockets are not allowed"
        )


def check_ratio(info: zipfile.ZipInfo, settings: Settings) -> None:
    if info.file_size <= RATIO_FLOOR_BYTES:
        return
    ratio = info.file_size / max(info.compress_size, 1)
    if ratio > settings.max_compression_ratio:
        raise IntakeError(
            info.filename,
            "compression-ratio",
            f"compresses {ratio:.0f}:1 (limit {settings.max_compression_ratio:g}:1): a zip bomb?",
        )


def check_members(archive: zipfile.ZipFile, budget: Budget, depth: int, prefix: str = "") -> None:
    """Check every entry of ``archive`` (and of archives nested in it) against the limits."""
    seen: set[PurePosixPath] = set()
    files: set[PurePosixPath] = set()
    folders: set[PurePosixPath] = set()
    for info in archive.infolist():
        shown = f"{prefix}{info.filename}"
        budget.take_entry(shown)
        path = entry_path(info)
        if path in seen:
            raise IntakeError(shown, "duplicate-entry", "the same name appears twice")
        seen.add(path)
        check_kind(info)
        # A file `a` beside a folder `a/` (or an entry `a/b`) cannot both be written.
        parents = set(path.parents) - {PurePosixPath(".")}
        if parents & files or (not info.is_dir() and path in folders):
            raise IntakeError(shown, "file-folder-clash", "a name is both a file and a folder")
        folders |= parents | ({path} if info.is_dir() else set())
        if info.is_dir():
            continue
        files.add(path)
        check_ratio(info, budget.settings)
        budget.take_bytes(shown, info.file_size)
        check_nested(archive, info, budget, depth, shown)


def check_nested(
    archive: zipfile.ZipFile, info: zipfile.ZipInfo, budget: Budget, depth: int, shown: str
) -> None:
    """A nested archive's contents count against the budget, whatever its name says."""
    head = read_entry(archive, info, 8)
    kind = "zip" if head.startswith(ZIP_MAGIC) else None
    kind = kind or next((k for magic, k in STREAM_MAGIC.items() if head.startswith(magic)), None)
    if kind is None:
        return
    if depth >= MAX_NESTING:
        raise IntakeError(shown, "nested-archive", f"archives nested more than {MAX_NESTING} deep")
    if kind == "zip":
        data = read_bounded(archive, info, shown)
        try:
            nested = zipfile.ZipFile(io.BytesIO(data))
        except zipfile.BadZipFile:
            return
        with nested:
            check_members(nested, budget, depth + 1, prefix=f"{shown}!")
        return
    budget.take_bytes(f"{shown} (inflated)", inflated_size(archive, info, kind, budget.bytes))


def inflated_size(archive: zipfile.ZipFile, info: zipfile.ZipInfo, kind: str, cap: int) -> int:
    """Bytes a gzip/bzip2/xz member inflates to, counting no further than just past ``cap``."""
    decompressor = {
        "gzip": lambda: zlib.decompressobj(16 + zlib.MAX_WBITS),
        "bzip2": bz2.BZ2Decompressor,
        "xz": lzma.LZMADecompressor,
    }[kind]()
    produced = 0
    with archive.open(info) as handle:
        while (chunk := _read_chunk(handle, info)) and not decompressor.eof:
            pending = chunk
            while True:
                try:
                    produced += len(decompressor.decompress(pending, COPY_CHUNK))
                except (zlib.error, OSError, EOFError, lzma.LZMAError):
                    return produced
                if produced > cap or decompressor.eof:
                    return produced
                if kind == "gzip":
                    pending = decompressor.unconsumed_tail
                    if not pending:
                        break
                else:
                    pending = b""
                    if decompressor.needs_input:
                        break
    return produced


def _read_chunk(handle, info: zipfile.ZipInfo) -> bytes:
    try:
        return handle.read(COPY_CHUNK)
    except CORRUPT_ENTRY_ERRORS as error:
        raise IntakeError(info.filename, "corrupt-entry", f"cannot be read: {error}") from error


def read_bounded(archive: zipfile.ZipFile, info: zipfile.ZipInfo, shown: str) -> bytes:
    data = read_entry(archive, info, info.file_size + 1)
    if len(data) > info.file_size:
        raise IntakeError(shown, "size-mismatch", "the entry holds more than it declares")
    return data


def extract(archive: zipfile.ZipFile, dest: Path, settings: Settings) -> None:
    """Write the checked entries under ``dest``; then make the whole tree read-only."""
    dest.mkdir(parents=True)
    left = settings.max_unzipped_bytes
    for info in archive.infolist():
        target = dest.joinpath(*entry_path(info).parts)
        if info.is_dir():
            target.mkdir(parents=True, exist_ok=True)
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        with archive.open(info) as source, target.open("xb") as sink:
            written = 0
            while chunk := _read_chunk(source, info):
                written += len(chunk)
                left -= len(chunk)
                if written > info.file_size or left < 0:
                    raise IntakeError(info.filename, "size-mismatch", "more data than declared")
                sink.write(chunk)
    make_read_only(dest)


def make_read_only(root: Path) -> None:
    """Files 0444 and folders 0555: readable by the sandbox's uid 65534, writable by nobody."""
    for path in sorted(root.rglob("*"), reverse=True):
        path.chmod(0o555 if path.is_dir() else 0o444)
    root.chmod(0o555)


def remove_tree(root: Path) -> None:
    """Delete a (read-only) extracted tree."""
    if not root.exists():
        return
    for path in [root, *root.rglob("*")]:
        if path.is_dir() and not path.is_symlink():
            path.chmod(0o755)
    shutil.rmtree(root)
