"""Submission intake: a zip (or folder) in, a checked, extracted, read-only submission out.

:func:`prepare_submission` is the only way a submission reaches a sandbox. The participant's
bytes are handled by :mod:`agent_runtime.intake`, through an
:class:`~submissions.intake.runner.IntakeRunner`: in this process for a participant's own zip, in
the sandbox for the service (``evaluator.validation``). Each rule has a short name, carried by
the :class:`~arena.errors.IntakeError` it raises together with the entry at fault;
``docs/submissions.md`` lists them all.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

from agent_runtime import intake as rules
from arena.config import IntakeSettings, SandboxSettings
from arena.errors import IntakeError
from arena.files import file_sha256
from sim.interface import AgentInterface
from submissions.intake.archive import make_read_only, remove_tree
from submissions.intake.contents import checked_contents, interface_of
from submissions.intake.dependencies import install_requirements
from submissions.intake.pack import pack_folder
from submissions.intake.porting import (
    missing_compat_names,
    porting_notes,
    read_scan,
    with_porting_notes,
)
from submissions.intake.runner import IntakeRunner, in_process, write_inputs
from submissions.intake.stacks import check_stack_name, read_stack

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
    # The content key of its requirements' folder (submissions.intake.dependencies), if any.
    deps_key: str | None = None


def prepare_submission(
    source: Path,
    dest: Path,
    intake: IntakeSettings,
    sandbox: SandboxSettings,
    data_dir: Path,
    *,
    runner: IntakeRunner = in_process,
    needs_training: bool = False,
    install: bool = True,
) -> PreparedSubmission:
    """Check ``source`` (a zip, or a folder zipped the same way), extract it into ``dest``
    (replacing what was there) and install its requirements (unless not ``install``).

    ``needs_training``: refuse a zip without ``train.py`` (an offline submission), before its
    requirements are installed. Raises :class:`~arena.errors.IntakeError` naming the entry and
    the rule at fault; nothing is left in ``dest`` then. Requirements are resolved for the
    ``sandbox``'s interpreter and kept under ``data_dir``.
    """
    source = Path(source)
    dest = Path(dest)
    if source.is_dir():
        with tempfile.TemporaryDirectory(prefix="arena-pack-") as tmp:
            return prepare_submission(
                pack_folder(source, Path(tmp) / "agent.zip"),
                dest,
                intake,
                sandbox,
                data_dir,
                runner=runner,
                needs_training=needs_training,
                install=install,
            )
    if not source.is_file():
        raise IntakeError(str(source), "not-found", "no such file")
    dest.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".intake-", dir=dest.parent))
    try:
        write_inputs(work / "in", intake, {rules.UPLOAD: source})
        verdict = runner("submission", work / "in", work / "out")
    except IntakeError as error:
        # A script that fails its checks after extraction: the porting notes are still told.
        try:
            notes = porting_notes(read_scan(work / "out"))
        finally:
            remove_tree(work)  # a zip that fails its checks leaves the previous extraction alone
        raise with_porting_notes(error, notes) from error
    except BaseException:
        remove_tree(work)
        raise
    notes: tuple[str, ...] = ()
    try:
        remove_tree(dest)
        (work / "out" / rules.SUBMISSION_DIR).rename(dest)
        make_read_only(dest)
        scan = read_scan(work / "out")
        notes = porting_notes(scan)
        contents = checked_contents(verdict)
        if needs_training and not contents.trains:
            raise IntakeError(
                rules.TRAIN_SCRIPT,
                "train-missing",
                "an offline (Track 2) submission holds train.py beside policy.py; the service "
                "runs it on the dataset before evaluating (docs/dataset.md)",
            )
        options = dict(contents.agent_options)
        stack_name = options.pop("stack", None)
        if stack_name is not None:
            check_stack_name(stack_name)
        interface = interface_of(options)
        missing = missing_compat_names(scan)  # after agent.yaml's checks: its format decides
        if missing is not None:
            raise missing
        installed = (
            install_requirements(
                contents.requirements or "",
                intake,
                sandbox,
                data_dir,
                runner,
                stack=read_stack(data_dir, stack_name) if stack_name is not None else None,
            )
            if install
            else None
        )
    except IntakeError as error:
        remove_tree(dest)
        raise with_porting_notes(error, notes) from error
    except BaseException:
        remove_tree(dest)
        raise
    finally:
        remove_tree(work)
    return PreparedSubmission(
        root=dest.resolve(),
        deps_dir=installed.folder if installed else None,
        deps_key=installed.key if installed else None,
        interface=interface,
        sha256=file_sha256(source),
        size=source.stat().st_size,
        explanation=contents.explanation,
        notes=notes,
        trains=contents.trains,
    )


def check_zip(path: Path, intake: IntakeSettings, sandbox: SandboxSettings) -> PreparedSubmission:
    """Every rule that can be judged from the zip alone (requirements are not installed);
    nothing is kept."""
    with tempfile.TemporaryDirectory(prefix="arena-check-") as tmp:
        work = Path(tmp)
        return prepare_submission(path, work / "submission", intake, sandbox, work, install=False)
