"""Submission intake: a zip (or folder) in, a checked, extracted, read-only submission out.

:func:`prepare_submission` is the only way a submission reaches a sandbox. Each rule it enforces
has a short name, carried by the :class:`~arena.errors.IntakeError` it raises together with
the entry at fault; ``docs/submissions.md`` lists them all.
"""

from __future__ import annotations

import hashlib
import tempfile
from dataclasses import dataclass
from pathlib import Path

from arena.config import Settings, get_settings
from arena.errors import IntakeError
from sim.interface import AgentInterface
from submissions.intake.archive import Budget, check_members, extract, open_zip, remove_tree
from submissions.intake.contents import (
    REQUIREMENTS,
    check_policy,
    check_train_script,
    load_explanation,
    load_interface,
    read_text,
)
from submissions.intake.dependencies import install_requirements
from submissions.intake.pack import pack_folder
from submissions.intake.porting import porting_notes, with_porting_notes

__all__ = ["IntakeError", "PreparedSubmission", "check_zip", "pack_folder", "prepare_submission"]


@dataclass(frozen=True)
class PreparedSubmission:
    """A submission that passed intake, ready to :func:`evaluator.sandbox.start`."""

    root: Path  # the extracted, read-only folder holding policy.py
    deps_dir: Path | None  # its installed requirements (read-only, shared by hash), if any
    interface: AgentInterface
    sha256: str  # of the zip's bytes
    size: int  # of the zip [bytes]
    explanation: str | None
    notes: tuple[str, ...] = ()  # porting help that does not reject (submissions.intake.porting)
    trains: bool = False  # holds train.py (Track 2: trained in the sandbox before evaluation)
    # The trained output its policy reads (ARENA_MODEL_DIR), once `train.py` has run.
    model_dir: Path | None = None


@dataclass(frozen=True)
class CheckedZip:
    interface: AgentInterface
    explanation: str | None
    requirements: str | None
    sha256: str
    size: int
    notes: tuple[str, ...] = ()
    trains: bool = False


def check_zip(path: Path, settings: Settings | None = None) -> CheckedZip:
    """Every rule that can be judged from the zip alone; nothing is written."""
    settings = settings or get_settings()
    with open_zip(path, settings) as archive:
        check_members(archive, Budget(settings), depth=0)
        notes = porting_notes(archive)
        try:
            check_policy(archive)
            trains = check_train_script(archive)
            interface = load_interface(archive)
            explanation = load_explanation(archive)
            requirements = read_text(archive, REQUIREMENTS)
        except IntakeError as error:
            raise with_porting_notes(error, notes) from error
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        while chunk := handle.read(1024**2):
            digest.update(chunk)
    return CheckedZip(
        interface,
        explanation,
        requirements,
        digest.hexdigest(),
        path.stat().st_size,
        notes,
        trains,
    )


def prepare_submission(
    source: Path, dest: Path, settings: Settings | None = None
) -> PreparedSubmission:
    """Check ``source`` (a zip, or a folder zipped the same way), extract it into ``dest``
    (replacing what was there) and install its requirements.

    Raises :class:`~arena.errors.IntakeError` naming the entry and the rule at fault.
    """
    settings = settings or get_settings()
    source = Path(source)
    dest = Path(dest)
    if source.is_dir():
        with tempfile.TemporaryDirectory(prefix="arena-pack-") as tmp:
            return prepare_submission(pack_folder(source, Path(tmp) / "agent.zip"), dest, settings)
    if not source.is_file():
        raise IntakeError(str(source), "not-found", "no such file")
    checked = check_zip(source, settings)
    remove_tree(dest)
    # Extract first: a zip that fails extraction must not leave installed requirements behind
    # (repeated rejected uploads would fill the disk at no cost to their quota).
    try:
        with open_zip(source, settings) as archive:
            extract(archive, dest, settings)
        deps_dir = install_requirements(checked.requirements or "", settings)
    except IntakeError as error:
        remove_tree(dest)
        raise with_porting_notes(error, checked.notes) from error
    except BaseException:
        remove_tree(dest)
        raise
    return PreparedSubmission(
        root=dest.resolve(),
        deps_dir=deps_dir,
        interface=checked.interface,
        sha256=checked.sha256,
        size=checked.size,
        explanation=checked.explanation,
        notes=checked.notes,
        trains=checked.trains,
    )
