"""The unsandboxed backend: the runner as a plain child process with rlimits only.

For participants trying their agent locally on a machine without Docker or bubblewrap, and as the
baseline of the sandbox benchmark. It gives no isolation at all (the agent sees the whole host as
the evaluating user), so the service refuses it: see :func:`evaluator.sandbox.check_service_kind`.

The agent runs on the same interpreter as under bubblewrap and in the agent image when this
machine has it (Debian's ``/usr/bin/python3`` with ``python3-numpy``), so it imports the same
libraries there as in the other sandboxes; elsewhere on the evaluator's own Python, whose numpy
and other packages may differ (the hello's versions in the log say which).
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys

from arena.config import SandboxKind, SandboxSettings
from evaluator.sandbox.backend import (
    RUNTIME_MAIN,
    TRAIN_SCRIPT,
    LaunchSpec,
    runtime_dir,
)
from evaluator.sandbox.bwrap_backend import RUNTIME_PYTHON
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

    def contract_gap(self, config: SandboxSettings) -> str | None:
        return "it does not isolate agents; use docker or bubblewrap"

    def unavailable_reason(self, config: SandboxSettings) -> str | None:
        return None

    def launch(self, spec: LaunchSpec) -> PopenSandbox:
        training = spec.training
        model = training.output if training is not None else spec.model
        env = spec.sandbox_env(
            os.defpath,
            deps=str(spec.deps),
            dataset=str(training.dataset) if training is not None else "",
            model=str(model),
        )
        # No private /tmp here: the submission folder is its home, the system's temporary
        # folder its scratch.
        env["HOME"] = str(spec.submission)
        env.pop("TMPDIR")
        env[LABELS_ENV] = encode_labels(spec.all_labels)
        if training is not None:
            command = [sys.executable, "-B", "-s", str(spec.submission / TRAIN_SCRIPT)]
        else:
            deps = ["--deps", str(spec.deps)] if spec.deps else []
            command = [
                agent_python(spec.config.agent_python_version),
                "-I",
                "-B",
                str(runtime_dir() / RUNTIME_MAIN),
                "--submission",
                str(spec.submission),
                *deps,
                *spec.format_args(),
            ]
        control, child_end = control_pair(spec.zygote)
        try:
            process = subprocess.Popen(
                command,
                **sandbox_streams(training is not None, child_end),
                cwd=spec.submission,
                env=env,
                start_new_session=True,
                preexec_fn=rlimit_setter(
                    spec.config.agent_memory_bytes,
                    None,
                    file_bytes=training.output_bytes if training else None,
                    cpus=spec.cpus,
                ),
            )
        finally:
            if child_end is not None:
                os.close(child_end)
        return PopenSandbox(
            process,
            spec.config.agent_log_tail_bytes,
            spec.instance_labels,
            control=control,
        )

    def cleanup(self, labels: dict[str, str], config: SandboxSettings) -> int:
        return kill_labelled(labels)


@functools.cache
def agent_python(version: str) -> str:
    """The sandboxes' interpreter when this machine has it at ``version`` with numpy, else ours."""
    try:
        probe = subprocess.run(
            [str(RUNTIME_PYTHON), "-I", "-c", "import sys, numpy; print(sys.version[:5])"],
            capture_output=True,
            text=True,
            timeout=60,
        )
    except (OSError, subprocess.TimeoutExpired):
        return sys.executable
    ok = probe.returncode == 0 and probe.stdout.strip().startswith(f"{version}.")
    return str(RUNTIME_PYTHON) if ok else sys.executable
