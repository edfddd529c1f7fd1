"""Where :mod:`agent_runtime.intake` and :mod:`agent_runtime.resolve` run: a
:class:`IntakeRunner` takes a mode, a folder of inputs (the zip or the wheels, and
``limits.json``; or the resolver's ``resolve.json``) and an empty output folder, and returns the
verdict ``report.json`` holds. The intake's modes are ``submission`` and ``wheels``; the
resolver's (:data:`RESOLVER_MODES`) ``download`` and ``build``, whose report is returned as it
is (a failed resolution is explained by ``submissions.intake.porting``).

:func:`in_process` is for participants' own zips on their own machine (``arena submission
check``, local evaluation): the checks in this process, the resolver as a child with a minimal
environment. The service runs both in the sandbox instead (``evaluator.validation.sandboxed``,
``evaluator.sandbox.resolver``), under memory, CPU, time, file-size and disk limits.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path
from typing import Protocol

from agent_runtime import intake as rules
from agent_runtime import resolve
from arena.config import IntakeSettings
from arena.errors import IntakeError
from submissions.intake.archive import limits

# report.json is ours, but written where the participant's bytes were handled: bounded too.
MAX_REPORT_BYTES = 1024**2
RESOLVER_MODES = ("download", "build")
# What a participant's machine needs to reach its package index (its proxies).
LOCAL_RESOLVER_VARIABLES = ("http_proxy", "https_proxy", "no_proxy", "HTTP_PROXY", "HTTPS_PROXY")
# A rejection's entry, rule and message are shown to the team: bounded like the rest.
MAX_REJECTION_CHARS = 4096


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


def read_sandbox_json(path: Path, max_bytes: int) -> dict | None:
    """A JSON object written where a participant's bytes were handled: not followed if it is a
    link, at most ``max_bytes``, None when it is absent or not a JSON object."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as handle:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        return None
    try:
        value = json.loads(data)
    except (ValueError, RecursionError):
        return None
    return value if isinstance(value, dict) else None


def read_report(output: Path) -> dict:
    """The verdict in ``output``; a rejection raised as IntakeError."""
    verdict = read_sandbox_json(output / rules.REPORT, MAX_REPORT_BYTES)
    if verdict is None:
        raise IntakeError(rules.ARCHIVE, "intake-crashed", "the check ended without a verdict")
    if verdict.get("ok") is not True:
        entry, rule, message = (verdict.get(k) for k in ("entry", "rule", "message"))
        if not all(isinstance(v, str) and len(v) <= MAX_REJECTION_CHARS for v in (entry, rule)):
            raise IntakeError(rules.ARCHIVE, "intake-crashed", "the check's verdict is malformed")
        raise IntakeError(entry, rule, str(message)[:MAX_REJECTION_CHARS])
    return verdict


def read_resolver_report(output: Path) -> dict:
    """The resolver's report (bounded: written where a team's requirements were handled)."""
    path = output / resolve.REPORT
    if not path.is_file() or path.stat().st_size > MAX_REPORT_BYTES:
        raise IntakeError(
            rules.REQUIREMENTS,
            "intake-crashed",
            "resolving the requirements ended without a report",
        )
    try:
        report = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as error:
        raise IntakeError(
            rules.REQUIREMENTS, "intake-crashed", "malformed resolver report"
        ) from error
    if not isinstance(report, dict):
        raise IntakeError(rules.REQUIREMENTS, "intake-crashed", "malformed resolver report")
    return report


def in_process(mode: str, inputs: Path, output: Path) -> dict:
    """Run the checks in this process, the resolver in a child with a minimal environment (no
    sandbox: for a participant's own zip on their own machine)."""
    output.mkdir(parents=True, exist_ok=True)
    if mode in RESOLVER_MODES:
        subprocess.run(
            [sys.executable, "-I", "-B", resolve.__file__, mode, str(inputs), str(output)],
            env={
                "PATH": os.defpath,
                **{k: v for k, v in os.environ.items() if k in LOCAL_RESOLVER_VARIABLES},
            },
            stdin=subprocess.DEVNULL,
            check=False,
        )
        return read_resolver_report(output)
    rules.main([mode, str(inputs), str(output)])
    return read_report(output)
