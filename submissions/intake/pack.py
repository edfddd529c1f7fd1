"""Zipping a submission folder the same way every time.

Entries are sorted, dated 1980-01-01 and given fixed permissions, so the same folder always gives
the same bytes (and the same sha256). Caches and editor/VCS clutter are left out; a symlink is an
error, as it would be in an uploaded zip.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

from arena.errors import IntakeError

SKIPPED_DIRS = {
    "__pycache__",
    ".git",
    ".hg",
    ".svn",
    ".mypy_cache",
    ".pytest_cache",
    ".ruff_cache",
    ".ipynb_checkpoints",
    ".venv",
    "venv",
    ".idea",
    ".vscode",
}
SKIPPED_FILES = {".DS_Store", "Thumbs.db"}
SKIPPED_SUFFIXES = (".pyc", ".pyo", ".swp", "~")
FIXED_TIME = (1980, 1, 1, 0, 0, 0)


def packed_files(folder: Path) -> list[Path]:
    """The files that go into the zip, relative to ``folder``, in zip order."""
    chosen = []
    for path in sorted(folder.rglob("*")):
        relative = path.relative_to(folder)
        if any(part in SKIPPED_DIRS for part in relative.parts):
            continue
        if path.is_symlink():
            raise IntakeError(relative.as_posix(), "symlink", "symbolic links are not allowed")
        if path.is_dir() or path.name in SKIPPED_FILES or path.name.endswith(SKIPPED_SUFFIXES):
            continue
        if not path.is_file():
            raise IntakeError(relative.as_posix(), "special-file", "not a regular file")
        chosen.append(relative)
    return chosen


def pack_folder(folder: Path, out: Path) -> Path:
    """Write ``folder`` as a deterministic zip at ``out``."""
    if not folder.is_dir():
        raise IntakeError(str(folder), "not-a-folder", "is not a folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for relative in packed_files(folder):
            info = zipfile.ZipInfo(relative.as_posix(), date_time=FIXED_TIME)
            info.external_attr = 0o100644 << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, (folder / relative).read_bytes())
    return out
