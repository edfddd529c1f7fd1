"""Looks for the service's secrets wherever a child process could find them (test data: the test
fills in SECRETS and FILES, then runs it as an agent's policy, a train.py, the intake's program
or a host tool's stand-in).

It answers one number per place, 1.0 where a secret is found there: its own environment and
command line, the secret files (readable at all), the environment of the namespace's init, of its
parent and of every process it can see (their command lines too).
"""

import json
import os
import sys

SECRETS = []  # filled in by the test
FILES = []  # filled in by the test
PLACES = (
    "environment",
    "command line",
    "secret files",
    "init's environment",
    "parent's environment",
    "any process",
)


def read(path):
    try:
        with open(path, "rb") as handle:
            return handle.read(1024**2)
    except OSError:
        return None


def holds_secret(data):
    return data is not None and any(secret.encode() in data for secret in SECRETS)


def findings():
    environ = b"\0".join(f"{k}={v}".encode() for k, v in os.environ.items())
    visible = []
    for pid in os.listdir("/proc"):
        if pid.isdigit() and int(pid) != os.getpid():
            visible += [read(f"/proc/{pid}/environ"), read(f"/proc/{pid}/cmdline")]
    found = (
        holds_secret(environ) or holds_secret(read("/proc/self/environ")),
        holds_secret(read("/proc/self/cmdline")),
        any(read(path) is not None for path in FILES),
        holds_secret(read("/proc/1/environ")),
        holds_secret(read(f"/proc/{os.getppid()}/environ")),
        any(map(holds_secret, visible)),
    )
    return [float(hit) for hit in found]


class Policy:
    def __init__(self):
        self.found = findings()

    def act(self, obs):
        return {agent: self.found for agent in obs}


if __name__ == "__main__":
    # A batch child: train.py (its output folder), the intake's program (its verdict's place),
    # a host tool's stand-in (the path given).
    target = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("ARENA_MODEL_DIR", "/model")
    if os.path.isdir(target):
        target = os.path.join(target, "report.json")
    with open(target, "w") as out:
        json.dump({"ok": True, "findings": findings()}, out)
