"""The host's side of the archive rules of :mod:`agent_runtime.intake` (which runs in the
sandbox): the limits from the settings, its rejections as :class:`~arena.errors.IntakeError`,
the API's cheap check of a zip's directory, and read-only trees.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from agent_runtime import intake as rules
from arena.config import IntakeSettings
from arena.errors import IntakeError

ARCHIVE = rules.ARCHIVE


def limits(intake: IntakeSettings) -> rules.Limits:
    return rules.Limits(
        max_zip_bytes=intake.max_zip_bytes,
        max_unzipped_bytes=intake.max_unzipped_bytes,
        max_entries=intake.max_zip_entries,
        max_compression_ratio=intake.max_compression_ratio,
        max_deps_bytes=intake.max_deps_bytes,
        max_deps_files=intake.max_deps_files,
        max_wheel_bytes=intake.max_wheel_bytes,
    )


@contextmanager
def rejections() -> Iterator[None]:
    """A rule broken inside, raised as the IntakeError the rest of the service knows."""
    try:
        yield
    except rules.Rejected as error:
        raise IntakeError(error.entry, error.rule, error.message) from error


def check_directory(path: Path, intake: IntakeSettings) -> None:
    """What the zip's directory alone tells (size, entries, names, kinds, declared sizes and
    ratios): no entry is inflated, so the API can afford it on every upload."""
    chosen = limits(intake)
    with rejections(), rules.open_zip(path, chosen) as archive:
        rules.check_directory(archive, chosen, rules.submission_budget(chosen))


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
