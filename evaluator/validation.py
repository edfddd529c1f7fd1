"""The service's intake: :mod:`agent_runtime.intake` run in the sandbox, never on the host.

Each step (the zip; then the wheels of its requirements) is one sandbox of the backend agents
run in: no network, uid 65534, read-only root, a size-capped ``/tmp``, the intake's own memory
limit (``ARENA_INTAKE_MEMORY_BYTES``), one CPU, a wall-time budget (``ARENA_INTAKE_TIMEOUT_S``),
no single file past the unzipped cap, and the output folder's bytes and files watched from here.
A step that breaks one of these limits is rejected naming it (``intake-memory``,
``intake-timeout``, ``intake-disk``, ``intake-files``); a broken sandbox is ours
(:class:`~arena.errors.SandboxUnavailable`, retried).

The sandbox's batch mode (:func:`evaluator.sandbox.start_training`: a script from a read-only
folder, inputs read-only, one writable output folder) runs it: the script is a two-line stub that
hands over to the runtime's ``intake.py``, mounted in every sandbox at ``/opt/arena``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

from agent_runtime import intake as rules
from arena.config import IntakeSettings, SandboxKind, SandboxSettings
from arena.errors import IntakeError
from evaluator.resolver import run_resolver
from evaluator.sandbox.backend import (
    DATASET_MOUNT,
    MODEL_MOUNT,
    RUNTIME_MOUNT,
    TRAIN_SCRIPT,
    Training,
)
from evaluator.sandbox.batch_folders import open_to_sandbox, output_usage, writable_by_sandbox
from submissions.intake import PreparedSubmission, prepare_submission
from submissions.intake.runner import RESOLVER_MODES, IntakeRunner, read_report

POLL_S = 0.1


def _stub(mode: str) -> str:
    return (
        "import runpy, sys\n"
        f"sys.argv = ['intake.py', {mode!r}, {DATASET_MOUNT!r}, {MODEL_MOUNT!r}]\n"
        f"runpy.run_path({RUNTIME_MOUNT + '/intake.py'!r}, run_name='__main__')\n"
    )


def intake_limits(
    intake: IntakeSettings, config: SandboxSettings, inputs: Path, output: Path
) -> tuple[SandboxSettings, Training]:
    """The sandbox limits of an intake step: its own memory and time; no file larger than what
    the zip (or the wheels) may unpack to."""
    memory = config.model_copy(update={"agent_memory_bytes": intake.intake_memory_bytes})
    file_cap = max(intake.max_unzipped_bytes, intake.max_deps_bytes)
    return memory, Training(inputs, output, intake.intake_timeout_s, file_cap)


def sandboxed(
    intake: IntakeSettings,
    config: SandboxSettings,
    data_dir: Path,
    kind: SandboxKind | str | None = None,
    labels: dict[str, str] | None = None,
) -> IntakeRunner:
    """An intake runner that runs each step in a sandbox of ``kind`` (owned by ``data_dir``)."""

    def run(mode: str, inputs: Path, output: Path) -> dict:
        from evaluator import sandbox

        if mode in RESOLVER_MODES:
            return run_resolver(
                mode,
                inputs,
                output,
                intake=intake,
                config=config,
                data_dir=data_dir,
                kind=kind,
                labels=labels,
            )

        limits, batch = intake_limits(intake, config, inputs, output)
        disk_cap = intake.max_unzipped_bytes if mode == "submission" else intake.max_deps_bytes
        files_cap = intake.max_zip_entries if mode == "submission" else intake.max_deps_files
        # Room for the report and the scratch copy of one nested archive.
        disk_cap, files_cap = 2 * disk_cap + 1024**2, files_cap + 16
        # A worker in a container makes the stub where the Docker daemon sees the same path.
        shared = config.sandbox_shared_dir
        if shared is not None:
            shared.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(prefix="arena-intake-stub-", dir=shared) as stub_dir:
            program = Path(stub_dir)
            (program / TRAIN_SCRIPT).write_text(_stub(mode))
            open_to_sandbox(program, inputs)
            writable_by_sandbox(output)
            started = time.monotonic()
            box = sandbox.start_training(
                SimpleNamespace(root=program, deps_dir=None),
                batch,
                config=limits,
                data_dir=data_dir,
                kind=kind,
                labels=labels,
            )
            try:
                while (status := box.exit_status(POLL_S)) is None:
                    if time.monotonic() - started > intake.intake_timeout_s:
                        raise IntakeError(
                            rules.ARCHIVE,
                            "intake-timeout",
                            f"checking took longer than {intake.intake_timeout_s:g} s",
                        )
                    size, count = output_usage(output)
                    if size > disk_cap:
                        raise IntakeError(
                            rules.ARCHIVE, "intake-disk", f"unpacks to more than {disk_cap} bytes"
                        )
                    if count > files_cap:
                        raise IntakeError(
                            rules.ARCHIVE, "intake-files", f"unpacks to more than {files_cap} files"
                        )
            finally:
                box.kill()
            log = box.logs()
        if status.oom_killed or (status.code != 0 and "MemoryError" in log):
            raise IntakeError(
                rules.ARCHIVE,
                "intake-memory",
                f"checking it needed more than {intake.intake_memory_bytes // 1024**2} MiB",
            )
        if status.code != 0:
            if "File too large" in log or status.code in (-25, 128 + 25):
                raise IntakeError(rules.ARCHIVE, "intake-disk", "a file unpacks past the cap")
            raise IntakeError(
                rules.ARCHIVE, "intake-crashed", f"the check {status.describe()}: {log[-300:]}"
            )
        return read_report(output)

    return run


def validate(
    upload: Path,
    dest: Path,
    intake: IntakeSettings,
    config: SandboxSettings,
    data_dir: Path,
    *,
    kind: SandboxKind | str | None = None,
    labels: dict[str, str] | None = None,
    needs_training: bool = False,
) -> PreparedSubmission:
    """:func:`~submissions.intake.prepare_submission` of ``upload`` into ``dest``, every step
    in the sandbox (of ``config``, owned by ``data_dir``, where the requirements are kept)."""
    return prepare_submission(
        upload,
        dest,
        intake,
        config,
        data_dir,
        runner=sandboxed(intake, config, data_dir, kind, labels),
        needs_training=needs_training,
    )
