"""Where :mod:`agent_runtime.intake` runs: a :class:`IntakeRunner` takes a mode, a folder of
inputs (the zip or the wheels, and ``limits.json``) and an empty output folder, and returns the
verdict ``report.json`` holds.

:func:`in_process` is for participants' own zips on their own machine (``arena submission
check``, local evaluation). The service runs it in the sandbox instead
(``evaluator.validation.sandboxed``), under memory, CPU, time, file-size and disk limits.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path
from typing import Protocol

from agent_runtime import intake as rules
from arena.config import IntakeSettings
from arena.errors import IntakeError
from submissions.intake.archive import limits

# report.json is ours, but written where the participant's bytes were handled: bounded too.
MAX_REPORT_BYTES = 1024**2


class IntakeRunner(Protocol):
    def __call__(self, mode: str, inputs: Path, output: Path) -> dict: ...


def write_inputs(inputs: Path, intake: IntakeSettings, files: dict[str, Path]) -> None:
    """``inputs/limits.json`` and each of ``files`` (name in the folder: host path), linked
    when the filesystem allows (a 100 MiB zip is not copied for nothing)."""
    inputs.mkdir(parents=True, exist_ok=True)
    (inputs / rules.LIMITS).write_text(json.dumps(dataclasses.asdict(limits(intake))))
    for name, source in files.items():
        target = inputs / name
        if source.is_dir():
            shutil.copytree(source, target)
            continue
        try:
            os.link(source, target)
        except OSError:
            shutil.copyfile(source, target)


def read_report(output: Path) -> dict:
    """The verdict in ``output``; a rejection raised as IntakeError."""
    path = output / rules.REPORT
    if not path.is_file() or path.stat().st_size > MAX_REPORT_BYTES:
        raise IntakeError(rules.ARCHIVE, "intake-crashed", "the check ended without a verdict")
    verdict = json.loads(path.read_text())
    if not verdict.get("ok"):
        raise IntakeError(verdict["entry"], verdict["rule"], verdict["message"])
    return verdict


def in_process(mode: str, inputs: Path, output: Path) -> dict:
    """Run the checks in this process (no sandbox: for a participant's own zip)."""
    output.mkdir(parents=True, exist_ok=True)
    rules.main([mode, str(inputs), str(output)])
    return read_report(output)
