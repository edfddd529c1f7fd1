"""The unsandboxed backend: the runner as a plain child process with rlimits only.

For participants trying their agent locally on a machine without Docker or bubblewrap, and as the
baseline of the sandbox benchmark. It gives no isolation at all (the agent sees the whole host as
the evaluating user), so the service refuses it: see :func:`evaluator.sandbox.check_service_kind`.
"""

from __future__ import annotations

import os
import subprocess
import sys

from arena.config import SandboxKind, Settings
from evaluator.sandbox.backend import (
    DATASET_ENV,
    MODEL_ENV,
    RUNTIME_ENV,
    RUNTIME_MAIN,
    TRAIN_SCRIPT,
    LaunchSpec,
    runtime_dir,
)
from evaluator.sandbox.subprocess_sandbox import (
    LABELS_ENV,
    PopenSandbox,
    control_pair,
    encode_labels,
    kill_labelled,
    rlimit_setter,
    sandbox_streams,
)


class ProcessBackend:
    kind = SandboxKind.process

    def contract_gap(self, settings: Settings) -> str | None:
        return "it does not isolate agents; use docker or bubblewrap"

    def unavailable_reason(self, settings: Settings) -> str | None:
        return None

    def launch(self, spec: LaunchSpec) -> PopenSandbox:
        env = {
            "PATH": os.defpath,
            **RUNTIME_ENV,
            "HOME": str(spec.submission),
            LABELS_ENV: encode_labels(spec.all_labels),
        }
        env.pop("TMPDIR")
        training = spec.training
        if training is not None:
            command = [sys.executable, "-B", "-s", str(spec.submission / TRAIN_SCRIPT)]
            env |= {
                DATASET_ENV: str(training.dataset),
                MODEL_ENV: str(training.output),
                "PYTHONUNBUFFERED": "1",
            }
            if spec.deps:
                env["PYTHONPATH"] = str(spec.deps)
        else:
            deps = ["--deps", str(spec.deps)] if spec.deps else []
            command = [
                sys.executable,
                "-I",
                "-B",
                str(runtime_dir() / RUNTIME_MAIN),
                "--submission",
                str(spec.submission),
                *deps,
                *spec.format_args(),
            ]
            if spec.model is not None:
                env[MODEL_ENV] = str(spec.model)
        control, child_end = control_pair(spec.zygote)
        try:
            process = subprocess.Popen(
                command,
                **sandbox_streams(training is not None, child_end),
                cwd=spec.submission,
                env=env,
                start_new_session=True,
                preexec_fn=rlimit_setter(
                    spec.settings.agent_memory_bytes,
                    None,
                    file_bytes=spec.settings.train_output_bytes if training else None,
                ),
            )
        finally:
            if child_end is not None:
                os.close(child_end)
        return PopenSandbox(
            process, spec.settings.agent_log_tail_bytes, spec.instance_labels, control=control
        )

    def cleanup(self, labels: dict[str, str]) -> int:
        return kill_labelled(labels)
