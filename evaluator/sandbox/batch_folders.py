"""The host side of a batch sandbox's folders (an intake step, the resolver): its program and
inputs readable by the sandbox user, its output folder writable by it, and what it wrote."""

from __future__ import annotations

import os
from pathlib import Path

# The sandbox user owns the output folder it writes (Docker and bubblewrap run as nobody).
SANDBOX_UID = 65534


def open_to_sandbox(program: Path, inputs: Path) -> None:
    """The sandbox user (not us) reads the stub and the inputs."""
    for root in (program, inputs):
        root.chmod(0o755)
        for path in root.rglob("*"):
            path.chmod(0o755 if path.is_dir() else 0o644)


def writable_by_sandbox(output: Path) -> None:
    output.mkdir(parents=True, exist_ok=True)
    if os.geteuid() == 0:
        os.chown(output, SANDBOX_UID, SANDBOX_UID)
    else:
        output.chmod(0o777)


def output_usage(folder: Path) -> tuple[int, int]:
    size = count = 0
    for path, _, files in os.walk(folder):
        for name in files:
            count += 1
            try:
                size += os.lstat(os.path.join(path, name)).st_size
            except FileNotFoundError:
                continue
    return size, count
