"""No secret reaches any child we start: not in its environment, its command line, nor any file
or process it can read (docs/deployment.md "Secrets", docs/sandbox.md).

Each child kind (agent, warm agent, training, upload validation, requirements resolver, a suite
build's host tool, an episode's fork server, `arena up`'s service processes and suite builder) is
spawned the way the service spawns it, from a process whose own initial environment holds every
secret as a plain variable (local use: the worst case, since ``/proc/<pid>/environ`` keeps a
process's initial environment whatever it does later), with the secrets also in files of mode
0400 as a deployment has them. The probe (``secret_probe.py``) looks for the secrets' values
everywhere the child can. Before the secrets were kept out, the sandboxes' own environments were
already explicit, but `arena up` gave its API and worker the admin token in their environment
and its suite builder the seed on its command line, and every host tool and every episode's fork
server inherited the whole environment.
"""

from __future__ import annotations

import json
import os
import secrets
import subprocess
import sys
from pathlib import Path

import pytest

from arena.config import SandboxKind, Settings
from tests.evaluator.sandbox.conftest import usable
from tests.evaluator.sandbox.secret_probe import PLACES

PROBE = Path(__file__).with_name("secret_probe.py")
# Where a child that isolates nothing (the process backend, a host tool, our own service
# processes, which read the secret files by design) is still held: what it is given.
GIVEN = {"environment", "command line"}
SANDBOXED = [
    pytest.param(kind, child, marks=mark, id=f"{child}-{kind.value}")
    for kind, mark in (
        (SandboxKind.bubblewrap, pytest.mark.bwrap),
        (SandboxKind.docker, pytest.mark.docker),
        (SandboxKind.process, ()),
    )
    for child in ("agent", "warm agent", "trainer", "intake")
]
# The requirements resolver runs only in an isolating sandbox (it refuses the process backend).
RESOLVER = [
    pytest.param(kind, "resolver", marks=mark, id=f"resolver-{kind.value}")
    for kind, mark in (
        (SandboxKind.bubblewrap, pytest.mark.bwrap),
        (SandboxKind.docker, pytest.mark.docker),
    )
]
HOST = ["host tool", "fork server", "service", "suite builder"]

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def planted(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, str], list[str], list]:
    """Every secret as the plain variable a local organiser may set, and as a 0400 file."""
    values = [f"secret-{name}-{secrets.token_hex(12)}" for name in ("a", "d", "b", "h")]
    admin, database, broker, seed = values
    env = {
        "ARENA_ADMIN_TOKEN": admin,
        "ARENA_DATABASE_URL": f"postgresql+psycopg://arena:{database}@127.0.0.1:9/arena",
        "ARENA_BROKER_URL": f"redis://:{broker}@127.0.0.1:9/0",
        "ARENA_HIDDEN_SEED": seed,
    }
    # Every secret but the passwords given apart from their URLs (the same secrets here).
    passwords = {"ARENA_DATABASE_PASSWORD", "ARENA_BROKER_PASSWORD"}
    assert set(env) == Settings.secret_env_names() - passwords
    folder = tmp_path_factory.mktemp("run-secrets")
    files = []
    for index, value in enumerate(values):
        path = folder / str(index)
        path.write_text(value + "\n")
        path.chmod(0o400)
        files.append(str(path))
    return env, values, files


def scan(child: str, kind: SandboxKind, planted, tmp_path: Path) -> set[str]:
    """Where the probe found a secret in ``child`` (spawned on ``kind``)."""
    env, values, files = planted
    probe = tmp_path / "secret_probe.py"
    probe.write_text(
        PROBE.read_text()
        .replace("SECRETS = []", f"SECRETS = {values!r}", 1)
        .replace("FILES = []", f"FILES = {files!r}", 1)
    )
    probe.chmod(0o644)
    tmp_path.chmod(0o755)
    work = tmp_path / "work"
    work.mkdir()
    # The environment a worker started by hand would have: everything of ours, the secrets too.
    started = {k: v for k, v in os.environ.items() if not k.startswith("ARENA_")} | env
    started["PYTHONPATH"] = str(Path(__file__).parents[3])
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "tests.evaluator.sandbox.secret_scan",
            child,
            kind.value,
            str(work),
            str(probe),
        ],
        env=started,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    found = json.loads(done.stdout.strip().splitlines()[-1])
    return {place for place, hit in zip(PLACES, found, strict=True) if hit}


@pytest.mark.parametrize(("kind", "child"), [*SANDBOXED, *RESOLVER])
def test_no_sandboxed_child_can_find_a_secret(kind, child, planted, tmp_path, settings) -> None:
    usable(kind, settings)
    found = scan(child, kind, planted, tmp_path)
    if kind is SandboxKind.process:
        # It isolates nothing (the service refuses it): it may read what its user reads.
        found &= GIVEN
    assert found == set(), f"a {child} on {kind.value} found a secret in: {sorted(found)}"


@pytest.mark.parametrize("child", HOST)
def test_no_host_child_is_given_a_secret(child, planted, tmp_path) -> None:
    found = scan(child, SandboxKind.process, planted, tmp_path)
    assert found & GIVEN == set(), f"the {child} was given a secret in: {sorted(found & GIVEN)}"
