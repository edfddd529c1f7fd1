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
from evaluator.sandbox.backend import RUNNER_PATH, RUNTIME_ENV, LaunchSpec
from evaluator.sandbox.subprocess_sandbox import (
    LABELS_ENV,
    PopenSandbox,
    control_pair,
    encode_labels,
    kill_labelled,
    rlimit_setter,
)


class ProcessBackend:
    kind = SandboxKind.process

    def unavailable_reason(self, settings: Settings) -> str | None:
        return None

    def launch(self, spec: LaunchSpec) -> PopenSandbox:
        deps = ["--deps", str(spec.deps)] if spec.deps else []
        command = [
            sys.executable,
            "-I",
            "-B",
            str(RUNNER_PATH),
            "--submission",
            str(spec.submission),
            *deps,
            *spec.format_args(),
        ]
        env = {
            "PATH": os.defpath,
            **RUNTIME_ENV,
            "HOME": str(spec.submission),
            LABELS_ENV: encode_labels(spec.all_labels),
        }
        env.pop("TMPDIR")
        control, child_end = control_pair(spec.zygote)
        try:
            process = subprocess.Popen(
                command,
                stdin=child_end or subprocess.PIPE,
                stdout=child_end or subprocess.PIPE,
                stderr=subprocess.PIPE,
                cwd=spec.submission,
                env=env,
                start_new_session=True,
                preexec_fn=rlimit_setter(spec.settings.agent_memory_bytes, None),
            )
        finally:
            if child_end is not None:
                os.close(child_end)
        return PopenSandbox(
            process, spec.settings.agent_log_tail_bytes, spec.instance_labels, control=control
        )

    def cleanup(self, labels: dict[str, str]) -> int:
        return kill_labelled(labels)
