"""One Track 2 training run: the submission's ``train.py`` in the sandbox, its end named.

The sandbox is the evaluation's (same backend, memory and CPU limits, no network) with the dataset
mounted read-only and the output folder writable. Here, on the host, the wall-time budget and the
output's caps (bytes, entries, depth: a bounded walk) are watched while it runs, and its end is
turned into a :class:`TrainingResult` whose ``failure`` is None or one named reason. ``on_progress``
is how a caller sees the elapsed time and the log tail, and how it stops a run (its worker is
shutting down, its claim was lost).
"""

from __future__ import annotations

import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from arena.config import SandboxKind, SandboxSettings, TrainingSettings
from arena.errors import ArenaError, DatasetError, IntakeError
from evaluator import sandbox
from evaluator.sandbox.backend import TRAIN_SCRIPT, ExitStatus, Training
from evaluator.training.checkpoint import hand_to_sandbox_user, restore
from evaluator.training.metrics import METRICS_FILE
from evaluator.training.model import OutputUsage, output_usage, regular_files

# How often the run is looked at (exit, budget) [s].
POLL_S = 0.25
# How often its output is measured [s]: a bounded walk (train_output_files entries at most), so
# neither it nor its frequency can delay the caller's progress report (the lease heartbeat).
OUTPUT_CHECK_S = 1.0


class TrainFailure(StrEnum):
    train_error = "train_error"  # train.py raised or exited non-zero
    train_timeout = "train_timeout"  # ran past ARENA_TRAIN_TIMEOUT_S
    train_memory_limit = "train_memory_limit"  # killed for, or failed on, its memory limit
    # output past ARENA_TRAIN_OUTPUT_BYTES, _FILES or _DEPTH
    train_output_too_large = "train_output_too_large"
    no_model_produced = "no_model_produced"  # exited 0 with no file in the output folder


@dataclass(frozen=True)
class TrainingResult:
    failure: TrainFailure | None
    detail: str  # why it failed, for the team ("" when it succeeded)
    log: str  # the tail of train.py's output (stdout and stderr)
    elapsed_s: float
    output_bytes: int

    @property
    def ok(self) -> bool:
        return self.failure is None


class TrainingStopped(ArenaError):
    """The caller's ``on_progress`` asked to stop: the sandbox was killed, nothing is judged."""


Progress = Callable[[float, str], bool]


def train(
    submission,
    dataset: Path,
    output: Path,
    *,
    training: TrainingSettings,
    config: SandboxSettings,
    data_dir: Path,
    kind: SandboxKind | str | None = None,
    labels: dict[str, str] | None = None,
    on_progress: Progress | None = None,
    progress_every_s: float = 2.0,
    resume_from: Path | None = None,
    seed: int = 0,
) -> TrainingResult:
    """Run ``submission``'s (a PreparedSubmission) ``train.py`` into the empty folder ``output``,
    which first receives the snapshot ``resume_from`` (:mod:`evaluator.training.checkpoint`)
    when the training resumes. It runs under ``training``'s limits, in a sandbox of ``config``
    owned by ``data_dir``. ``seed`` reaches ``train.py`` as ``ARENA_TRAIN_SEED``.

    ``on_progress(elapsed_s, log_tail)`` is called every ``progress_every_s``; returning False
    kills the run and raises :class:`TrainingStopped`. Raises
    :class:`~arena.errors.SandboxUnavailable` when the sandbox cannot start (ours, retried).
    """
    if not submission.trains:
        raise IntakeError(TRAIN_SCRIPT, "train-missing", "the submission has no train.py to run")
    dataset = Path(dataset)
    if not dataset.is_dir():
        raise DatasetError(
            f"the training dataset {dataset} is not a folder (build one with `arena dataset "
            "build --out DIR`)"
        )
    _writable_output(Path(output))
    if resume_from is not None:
        restore(resume_from, Path(output))
    caps = _Caps.of(training)
    started = time.monotonic()
    run = Training(
        dataset,
        Path(output),
        training.train_timeout_s,
        training.train_output_bytes,
        training.train_gpu,
        seed,
    )
    box = sandbox.start_training(
        submission, run, config=config, data_dir=data_dir, kind=kind, labels=labels
    )
    next_report = started + progress_every_s
    next_check = started + OUTPUT_CHECK_S
    try:
        while (status := box.exit_status(POLL_S)) is None:
            now = time.monotonic()
            elapsed = now - started
            if elapsed > training.train_timeout_s:
                return _ended(
                    box,
                    output,
                    started,
                    TrainFailure.train_timeout,
                    f"training ran past its budget of {training.train_timeout_s:g} s",
                    caps,
                )
            if now >= next_check:
                next_check = now + OUTPUT_CHECK_S
                past = caps.past(output)
                if past:
                    return _ended(
                        box,
                        output,
                        started,
                        TrainFailure.train_output_too_large,
                        f"the output folder grew past its caps: {past}",
                        caps,
                    )
            if on_progress is not None and now >= next_report:
                next_report = now + progress_every_s
                if not on_progress(elapsed, box.logs()):
                    box.kill()
                    raise TrainingStopped
        box.kill()
        return _judged(status, box.logs(), output, time.monotonic() - started, caps)
    finally:
        box.kill()


def _writable_output(output: Path) -> None:
    output.mkdir(parents=True, exist_ok=True)
    if any(output.iterdir()):
        raise DatasetError(f"the output folder {output} is not empty")
    hand_to_sandbox_user(output)


@dataclass(frozen=True)
class _Caps:
    bytes: int
    entries: int
    depth: int

    @classmethod
    def of(cls, training: TrainingSettings) -> _Caps:
        return cls(
            training.train_output_bytes, training.train_output_files, training.train_output_depth
        )

    def usage(self, output: Path) -> OutputUsage:
        return output_usage(output, self.entries)

    def past(self, output: Path) -> str | None:
        return self.usage(output).over(self.bytes, self.entries, self.depth)


def _ended(box, output: Path, started: float, failure: TrainFailure, detail: str, caps: _Caps):
    box.kill()
    return TrainingResult(
        failure, detail, box.logs(), time.monotonic() - started, caps.usage(output).bytes
    )


def _judged(
    status: ExitStatus, log: str, output: Path, elapsed_s: float, caps: _Caps
) -> TrainingResult:
    usage = caps.usage(output)
    size = usage.bytes
    cap = caps.bytes

    def result(failure: TrainFailure | None, detail: str = "") -> TrainingResult:
        return TrainingResult(failure, detail, log, elapsed_s, size)

    if status.oom_killed or (status.code != 0 and _ran_out_of_memory(log)):
        return result(
            TrainFailure.train_memory_limit,
            "train.py " + status.describe()
            if status.oom_killed
            else "train.py ran out of memory (MemoryError)",
        )
    if status.code != 0:
        if _file_too_large(status, log):
            return result(
                TrainFailure.train_output_too_large,
                f"train.py wrote a file past the output cap of {cap} bytes",
            )
        return result(TrainFailure.train_error, f"train.py {status.describe()}")
    past = usage.over(caps.bytes, caps.entries, caps.depth)
    if past:
        return result(TrainFailure.train_output_too_large, f"the output folder holds {past}")
    if not [path for path in regular_files(output) if path != Path(output) / METRICS_FILE]:
        return result(
            TrainFailure.no_model_produced,
            "train.py finished but wrote no file into the output folder (ARENA_MODEL_DIR) "
            f"besides {METRICS_FILE} (its curves, not a model)",
        )
    return result(None)


def _ran_out_of_memory(log: str) -> bool:
    lines = [line for line in log.strip().splitlines() if line.strip()]
    return bool(lines) and lines[-1].startswith("MemoryError")


def _file_too_large(status: ExitStatus, log: str) -> bool:
    """SIGXFSZ, or Python's own error when it ignores the signal (EFBIG)."""
    killed = status.code is not None and signal.SIGXFSZ in (-status.code, status.code - 128)
    return killed or "File too large" in log
