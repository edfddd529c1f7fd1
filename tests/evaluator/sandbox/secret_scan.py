"""Spawns one kind of child the way the service does and prints what the secret probe found in
it (tests/evaluator/sandbox/test_child_environment.py runs this in a process whose own initial
environment holds every secret as a plain variable: the worst local case).

    python -m tests.evaluator.sandbox.secret_scan CHILD SANDBOX WORKDIR PROBE
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import shutil
import stat
import sys
import time
from pathlib import Path
from types import SimpleNamespace

from arena.config import SandboxKind, Settings, get_settings
from evaluator import sandbox, validation
from evaluator.sandbox.backend import TRAIN_SCRIPT, Training
from submissions.intake import prepare_submission
from submissions.sample import sample_observation
from tests.evaluator.sandbox.test_warm import episode, zygote
from tests.settings import with_fields

LABELS = {"driving-arena.test": "secret-scan"}


def _settings(work: Path) -> Settings:
    return with_fields(
        Settings.load(env_file=None),
        storage={"data_dir": work / "data"},
        sandbox={"init_timeout_s": 60.0, "step_timeout_s": 30.0},
    )


def _submission(work: Path, probe: Path, settings: Settings):
    source = work / "src"
    source.mkdir()
    shutil.copy(probe, source / "policy.py")
    return prepare_submission(
        source, work / "submission", settings.intake, settings.sandbox, work / "data"
    )


def _open(folder: Path) -> None:
    """What the sandbox's uid 65534 reads and writes (the test's folders are private)."""
    folder.mkdir(parents=True, exist_ok=True)
    for path in [folder, *folder.rglob("*")]:
        path.chmod(0o777 if path.is_dir() else 0o666)
    for parent in folder.parents:
        if parent.stat().st_mode & stat.S_IXOTH == 0:
            parent.chmod(parent.stat().st_mode | stat.S_IXOTH)


def agent(kind: SandboxKind, work: Path, probe: Path) -> list[float]:
    settings = _settings(work)
    submission = _submission(work, probe, settings)
    with sandbox.start(
        submission,
        config=settings.sandbox,
        data_dir=settings.storage.resolved_data_dir,
        kind=kind,
        labels=LABELS,
    ) as handle:
        handle.reset()
        return handle.act(sample_observation())["Agent_0"]


def warm_agent(kind: SandboxKind, work: Path, probe: Path) -> list[float]:
    settings = _settings(work)
    submission = _submission(work, probe, settings)
    with zygote(submission, kind, settings, LABELS) as warm:
        return episode(warm, settings)[0]["Agent_0"]


def trainer(kind: SandboxKind, work: Path, probe: Path) -> list[float]:
    settings = _settings(work)
    program, dataset, output = work / "program", work / "dataset", work / "output"
    program.mkdir()
    shutil.copy(probe, program / TRAIN_SCRIPT)
    for folder in (program, dataset, output):
        _open(folder)
    box = sandbox.start_training(
        SimpleNamespace(root=program, deps_dir=None),
        Training(dataset, output, timeout_s=120.0, output_bytes=1024**2),
        config=settings.sandbox,
        data_dir=settings.storage.resolved_data_dir,
        kind=kind,
        labels=LABELS,
    )
    return _finished(box, output)


def _finished(box, output: Path) -> list[float]:
    """The batch child's findings, once it ended (killed after two minutes)."""
    try:
        deadline = time.monotonic() + 120.0
        while box.exit_status(0.2) is None and time.monotonic() < deadline:
            pass
    finally:
        box.kill()
    return json.loads((output / "report.json").read_text())["findings"]


def intake(kind: SandboxKind, work: Path, probe: Path) -> list[float]:
    """The validation's own launch (limits, folders, stub), with the probe as its program."""
    settings = _settings(work)
    validation._stub = lambda mode: probe.read_text()
    inputs, output = work / "inputs", work / "output"
    _open(inputs)
    _open(output)
    run = validation.sandboxed(
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
        kind=kind,
        labels=LABELS,
    )
    return run("submission", inputs, output)["findings"]


def resolver(kind: SandboxKind, work: Path, probe: Path) -> list[float]:
    """The requirements resolver's launch (evaluator/resolver.py: its limits, mounts, pip and
    index folders), with the probe as its program."""
    from evaluator import resolver as resolvers

    settings = _settings(work)
    resolvers._stub = lambda mode: probe.read_text()
    inputs, output, program = work / "inputs", work / "output", work / "program"
    for folder in (inputs, program):
        folder.mkdir()
    request = {"requirements": [], "index_urls": [], "find_links": [], "constraints": []}
    (inputs / "resolve.json").write_text(json.dumps(request))
    box = resolvers.spawn_resolver(
        "build",
        inputs,
        output,
        program,
        intake=settings.intake,
        config=settings.sandbox,
        data_dir=settings.storage.resolved_data_dir,
        kind=kind,
        labels=LABELS,
    )
    return _finished(box, output)


def host_tool(kind: SandboxKind, work: Path, probe: Path) -> list[float]:
    """netconvert as a suite build runs it, through a stand-in that runs the probe first and
    then the real tool."""
    # deferred: the stand-in must be on PATH before the module looks netconvert up
    from scenarios.maps import build_map

    bin_dir, report = work / "bin", work / "tool.json"
    bin_dir.mkdir()
    real = shutil.which("netconvert")
    stand_in = bin_dir / "netconvert"
    stand_in.write_text(f'#!/bin/sh\n"{sys.executable}" "{probe}" "{report}"\nexec "{real}" "$@"\n')
    stand_in.chmod(0o755)
    os.environ["PATH"] = f"{bin_dir}{os.pathsep}{os.environ['PATH']}"
    build_map("highway_2lane", work / "cache")
    return json.loads(report.read_text())["findings"]


def _probe_in_fork_server(probe: str, conn) -> None:
    namespace: dict = {}
    exec(compile(probe, "secret_probe", "exec"), namespace)
    conn.send(namespace["findings"]())


def fork_server(kind: SandboxKind, work: Path, probe: Path) -> list[float]:
    """A child of multiprocessing's fork server, as every episode's simulator is
    (sim/isolation.py), in a process that read its settings as entry points do."""
    get_settings()
    ctx = mp.get_context("forkserver")
    receiver, sender = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_probe_in_fork_server, args=(probe.read_text(), sender))
    child.start()
    found = receiver.recv()
    child.join()
    return found


def service(kind: SandboxKind, work: Path, probe: Path) -> list[float]:
    """`arena up`'s API and worker: their environment and command line as it starts them."""
    from server import embedded

    settings = get_settings()
    data = work / "data"
    data.mkdir()
    report = work / "service.json"
    env = embedded.service_environment(settings, data, embedded.secrets_folder(data))
    child = embedded._start_child([sys.executable, str(probe), str(report), "worker"], env)
    child.wait()
    return json.loads(report.read_text())["findings"]


def suite_builder(kind: SandboxKind, work: Path, probe: Path) -> list[float]:
    """`arena up`'s build of the hidden suite from the secret seed: the probe stands in for the
    `arena` command it runs, with the same environment and arguments."""
    from rich.console import Console

    from server import embedded

    settings = get_settings()
    data = work / "data"
    data.mkdir()
    report = work / "builder.json"
    embedded.ARENA = [sys.executable, str(probe), str(report)]
    env = embedded.service_environment(settings, data, embedded.secrets_folder(data))
    embedded._hidden_suite(Console(quiet=True), settings.suites, data, env)
    return json.loads(report.read_text())["findings"]


CHILDREN = {
    "agent": agent,
    "warm agent": warm_agent,
    "trainer": trainer,
    "intake": intake,
    "resolver": resolver,
    "host tool": host_tool,
    "fork server": fork_server,
    "service": service,
    "suite builder": suite_builder,
}

if __name__ == "__main__":
    child, kind, work, probe = sys.argv[1:5]
    found = CHILDREN[child](SandboxKind(kind), Path(work), Path(probe))
    print(json.dumps(found))
