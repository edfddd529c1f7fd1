"""Fault campaign: the service evaluates submissions while its parts are killed and restarted.

Starts its own PostgreSQL and Redis on spare loopback ports (the machine's shared instances are
never touched), an API and two workers (separate data folders, artifact store in the database)
and, in turn: SIGKILLs a worker holding a scenario (and restarts it, as a supervisor would),
kills an agent's sandbox from outside, restarts the broker (no persistence: every queued message
is lost) and the database (immediate shutdown, as a crash). Then it runs the embedded service
(`arena up`) on the same database and broker, SIGTERMs it and SIGKILLs it mid-evaluation, checks
that none of its processes or sandboxes outlive it, and restarts it.

Each fault prints its recovery time: from the fault until the work resumes (the lost scenario is
claimed again, the next scenario is claimed or finishes). At the end every submission must be
scored or failed with a named reason, no (run, scenario) is recorded twice, nothing is left
`running` and no process or container of the campaign remains. The last line is
``faults_injected=<n> survived=<n> lost=<n> duplicates=<n> stuck=<n> leftovers=<n>
max_recovery_s=<s>``.

    python bench/faults.py [--sandbox docker|bubblewrap] [--timeout 900] [--lease-seconds 30]
        [--reaper-interval-s 10]

Loopback only; bounded by ``--timeout`` (everything it started is stopped, even on Ctrl-C).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import os
import pwd
import re
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import httpx
from _prerequisites import require, tool
from sqlalchemy import func, select
from sqlalchemy.exc import SQLAlchemyError

from arena.config import ArtifactBackend, SandboxKind, Settings, get_settings
from arena.errors import SandboxUnavailable
from arena.settings_changes import env_only, with_fields
from arena.suite import SHIPPED_PUBLIC_DIR
from evaluator.sandbox import check_service_kind
from evaluator.sandbox.backend import SANDBOX_LABEL
from evaluator.sandbox.subprocess_sandbox import LABELS_ENV, labelled_pids
from server.core.db import Database
from server.core.migrate import upgrade_database
from server.models import EvaluationRun, ScenarioResult, Score, Submission
from server.processes import (
    ARENA,
    EXAMPLES,
    bearer,
    cut_suite,
    environment,
    free_port,
    shared_dir,
    start,
    start_worker,
    stop,
    upload_folder,
)
from server.services import teams

# [s] The paced agent's pause per step: ~300 steps make a scenario last seconds, long enough
# for a fault to land mid-episode (the examples finish one in about a second).
PACE_S = 0.02
# [s] The longest one upload's validation may take (its sandboxed intake).
VALIDATION_LIMIT_S = 180.0
# [s] The longest a fault may take to recover before it counts as not survived.
RECOVERY_LIMIT_S = 120.0
# [s] How long a sandbox runs before it is killed: past the agent's start-up, mid-episode.
SANDBOX_SETTLE_S = 2.0
# [s] How long the database stays down.
DATABASE_DOWN_S = 3.0
# [s] How long a stopped embedded service may take until none of its processes remain.
EXIT_LIMIT_S = 60.0
# [s] How long a service process may take to stop after SIGTERM before it is SIGKILLed.
STOP_LIMIT_S = 60.0
# [s] How long stopped processes' children may take to exit before they count as left over.
LEFTOVER_GRACE_S = 10.0
POLL_S = 0.2
FINAL_STATES = {"scored", "failed"}


class CampaignTimeout(Exception):
    """The campaign ran past --timeout."""


@dataclass
class FaultResult:
    name: str
    recovery_s: float | None  # None: progress never resumed within RECOVERY_LIMIT_S
    outcome: str
    clean: bool = True  # False: a process or sandbox outlived what was killed

    @property
    def survived(self) -> bool:
        return self.recovery_s is not None and self.clean

    def line(self) -> str:
        shown = "-" if self.recovery_s is None else f"{self.recovery_s:.1f}"
        verdict = "survived" if self.survived else "NOT SURVIVED"
        return f"fault {self.name:<18} recovery_s={shown:<6} {verdict}: {self.outcome}"


def wait_until(condition: Callable[[], object], limit_s: float) -> object | None:
    """Poll ``condition`` until it returns something true (returned), or None after limit_s."""
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        found = condition()
        if found:
            return found
        time.sleep(POLL_S)
    return None


# --- private PostgreSQL and Redis -----------------------------------------------------------


class PrivatePostgres:
    """A throw-away cluster in ``root`` on 127.0.0.1:``port`` (trust auth). initdb refuses to run
    as root, so as root the cluster runs as the ``postgres`` user."""

    def __init__(self, root: Path, port: int) -> None:
        self.data = root / "pgdata"
        self.sockets = root / "pgsock"
        self.log = root / "postgres.log"
        self.port = port
        self.bin = _postgres_bin()
        self.user = "postgres" if os.geteuid() == 0 else None
        self.process: subprocess.Popen | None = None

    def url(self, database: str) -> str:
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{database}"

    def init(self) -> None:
        for folder in (self.data, self.sockets):
            folder.mkdir()
            if self.user:
                entry = pwd.getpwnam(self.user)
                os.chown(folder, entry.pw_uid, entry.pw_gid)
        subprocess.run(
            [self.bin / "initdb", "-D", self.data, "-U", "postgres", "--auth=trust", "-E", "UTF8"],
            check=True,
            capture_output=True,
            user=self.user,
        )

    def start(self) -> None:
        command = [self.bin / "postgres", "-D", self.data, "-p", str(self.port)]
        command += ["-h", "127.0.0.1", "-k", self.sockets]
        with self.log.open("ab") as log:
            self.process = subprocess.Popen(
                command, stdout=log, stderr=log, user=self.user, start_new_session=True, env={}
            )
        if not wait_until(self._ready, 30):
            raise RuntimeError(f"PostgreSQL did not start, see {self.log}")

    def _ready(self) -> bool:
        # deferred: each broker, database or daemon client is needed only by its own fault
        import psycopg

        try:
            with psycopg.connect(f"postgresql://postgres@127.0.0.1:{self.port}/postgres"):
                return True
        except psycopg.OperationalError:
            return False

    def create_database(self, name: str) -> None:
        # deferred: each broker, database or daemon client is needed only by its own fault
        import psycopg

        dsn = f"postgresql://postgres@127.0.0.1:{self.port}/postgres"
        with psycopg.connect(dsn, autocommit=True) as connection:
            connection.execute(f'CREATE DATABASE "{name}"')

    def crash(self) -> None:
        """Immediate shutdown (SIGQUIT): no checkpoint, the next start recovers from the WAL."""
        self.stop(signal.SIGQUIT)

    def stop(self, sig: int = signal.SIGINT) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(sig)
            self.process.wait(timeout=60)


def _postgres_bin() -> Path | None:
    """The folder of PostgreSQL's server programs, None when not installed."""
    found = sorted(Path("/usr/lib/postgresql").glob("*/bin/postgres"))
    if found:
        return found[-1].parent
    initdb = shutil.which("initdb")
    return Path(initdb).parent if initdb else None


class PrivateRedis:
    """redis-server on 127.0.0.1:``port`` without persistence: a restart loses every message."""

    def __init__(self, root: Path, port: int) -> None:
        self.root = root
        self.port = port
        self.process: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> None:
        command = ["redis-server", "--port", str(self.port), "--bind", "127.0.0.1"]
        command += ["--save", "", "--appendonly", "no", "--dir", str(self.root)]
        self.process = subprocess.Popen(command, stdout=subprocess.DEVNULL, start_new_session=True)
        if not wait_until(self._ready, 30):
            raise RuntimeError("redis-server did not start")

    def _ready(self) -> bool:
        # deferred: each broker, database or daemon client is needed only by its own fault
        import redis

        try:
            return bool(redis.Redis(port=self.port).ping())
        except redis.ConnectionError:
            return False

    def queued(self) -> int:
        # deferred: each broker, database or daemon client is needed only by its own fault
        import redis

        return int(redis.Redis(port=self.port).llen("arena"))

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait(timeout=30)


# --- what the campaign watches --------------------------------------------------------------


class Row(NamedTuple):
    """A scenario result as the campaign watches it."""

    status: str
    worker: str  # the claim's holder while running
    claims: int  # claims so far
    reason: str


Results = dict[tuple[int, str], Row]  # (run, scenario) -> its row


class Ledger:
    """The campaign's view of the database: claims and results, tolerant of an outage."""

    def __init__(self, url: str) -> None:
        self.db = Database(url)

    def results(self) -> Results | None:
        """Every scenario result; None while the database is down."""
        columns = (ScenarioResult.status, ScenarioResult.worker, ScenarioResult.claim_number)
        try:
            with self.db.session() as session:
                rows = session.execute(
                    select(
                        ScenarioResult.run_id,
                        ScenarioResult.scenario_id,
                        *columns,
                        ScenarioResult.reason,
                    )
                ).all()
        except SQLAlchemyError:
            return None
        return {(r[0], r[1]): Row(str(r[2]), r[3], r[4], r[5]) for r in rows}

    def held(self) -> Results:
        """The scenarios a worker holds."""
        results = self.results() or {}
        return {key: row for key, row in results.items() if row.status == "running" and row.worker}

    def new_claim(self, before: Results) -> str | None:
        """A claim made since the snapshot ``before``: work is handed out again."""
        for key, row in (self.results() or {}).items():
            if key not in before or row.claims > before[key].claims:
                return f"{key[1]} of run {key[0]} claimed (claim {row.claims})"
        return None

    def finished_since(self, before: Results, only: tuple[int, str] | None = None) -> str | None:
        """A scenario (``only``, if given) running in ``before`` and finished now."""
        for key, row in (self.results() or {}).items():
            old = before.get(key)
            if only not in (None, key) or old is None or old.status != "running":
                continue
            if row.status != "running":
                return f"{key[1]} of run {key[0]} finished ({row.status}, {row.reason})"
        return None

    def upload_folders(self, run_ids: set[int]) -> dict[int, str]:
        """Run -> the folder workers prepare its submission in: named after the zip's digest
        (server/worker/local.py)."""
        with self.db.session() as session:
            rows = session.execute(
                select(EvaluationRun.id, Submission.file_sha256)
                .join(Submission, Submission.id == EvaluationRun.submission_id)
                .where(EvaluationRun.id.in_(run_ids))
            ).all()
        return dict(rows)

    def submissions(self, ids: list[int]) -> dict[int, tuple[str, str]]:
        with self.db.session() as session:
            rows = session.execute(
                select(Submission.id, Submission.status, Submission.status_reason).where(
                    Submission.id.in_(ids)
                )
            ).all()
        return {r[0]: (str(r[1]), r[2]) for r in rows}

    def integrity(self) -> tuple[int, int]:
        """(duplicates, stuck): a scenario recorded twice in a run, a submission evaluated by two
        runs, a run scored twice; rows still running or queued."""
        with self.db.session() as session:
            per_scenario = (
                select(func.count())
                .select_from(ScenarioResult)
                .group_by(ScenarioResult.run_id, ScenarioResult.scenario_id)
            )
            per_submission = (
                select(func.count())
                .select_from(EvaluationRun)
                .group_by(EvaluationRun.submission_id)
            )
            per_run = select(func.count()).select_from(Score).group_by(Score.run_id)
            duplicates = sum(
                max(0, count - 1)
                for query in (per_scenario, per_submission, per_run)
                for count in session.scalars(query)
            )
            stuck = (
                session.scalar(select(func.count()).where(ScenarioResult.status == "running"))
                + session.scalar(
                    select(func.count()).where(EvaluationRun.status.in_(["queued", "running"]))
                )
                + session.scalar(
                    select(func.count()).where(
                        Submission.status.in_(["received", "queued", "running"])
                    )
                )
            )
        return duplicates, stuck


def campaign_processes(root: Path) -> list[int]:
    """Live processes started for the campaign's service: their environment or command line
    names one of its folders (its own PostgreSQL and Redis excepted)."""
    marker = str(root).encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            environ = (entry / "environ").read_bytes()
            cmdline = (entry / "cmdline").read_bytes()
            state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state in ("Z", "X") or b"postgres" in cmdline or b"redis-server" in cmdline:
            continue
        if marker in environ or marker in cmdline:
            found.append(int(entry.name))
    return found


@dataclass
class Sandbox:
    """An agent sandbox of the campaign: the worker that started it, how to kill it from outside
    (as the OOM killer or an operator would) and how to remove it altogether."""

    key: str  # the container's id or the process's pid
    driver: tuple[str, str]  # the worker (``host:pid``, as claims name it) and upload folder
    running: bool
    labels: str  # its labels beyond the sandbox label, shown when it is left over
    kill: Callable[[], None]
    remove: Callable[[], None]


def campaign_sandboxes(root: Path, kind: SandboxKind) -> list[Sandbox]:
    """Agent sandboxes (running or stopped) that mount one of the campaign's folders."""
    found = []
    if kind is SandboxKind.docker:
        # deferred: each broker, database or daemon client is needed only by its own fault
        from evaluator.sandbox.docker_backend import docker_client

        # Sparse: from the listing alone, no inspection that a container ending meanwhile fails.
        containers = docker_client().containers.list(
            all=True, sparse=True, filters={"label": f"{SANDBOX_LABEL}=1"}
        )
        for container in containers:
            sources = [m.get("Source", "") for m in container.attrs.get("Mounts") or []]
            if any(s.startswith(str(root)) for s in sources):
                driver = _driver_of(" ".join(sources))
                running = container.attrs.get("State") == "running"
                kill = _gone_ok(container.kill)
                remove = _gone_ok(functools.partial(container.remove, force=True))
                labels = _shown_labels(container.attrs.get("Labels") or {})
                found.append(Sandbox(container.id[:12], driver, running, labels, kill, remove))
        return found
    labelled = set(labelled_pids({SANDBOX_LABEL: "1"}))
    for pid in labelled:
        try:
            outermost = _parent_of(pid) not in labelled
            sources = _bound_folders(pid)
            labels = _shown_labels(dict(_label_pairs(pid)))
        except OSError:
            continue  # ended meanwhile
        if not outermost or not any(s.startswith(str(root)) for s in sources):
            continue
        # The outermost bwrap: its namespace's other processes die with it (--die-with-parent).
        kill = functools.partial(_kill_if_alive, pid)
        driver = _driver_of(" ".join(sources))
        found.append(Sandbox(str(pid), driver, True, labels, kill, kill))
    return found


def _shown_labels(labels: dict[str, str]) -> str:
    return " ".join(f"{k}={v}" for k, v in sorted(labels.items()) if k != SANDBOX_LABEL)


def _label_pairs(pid: int) -> list[tuple[str, str]]:
    """The labels a sandbox process carries in its environment (subprocess_sandbox's)."""
    prefix = f"{LABELS_ENV}="
    for variable in Path(f"/proc/{pid}/environ").read_bytes().decode(errors="replace").split("\0"):
        if variable.startswith(prefix):
            return [tuple(p.split("=", 1)) for p in variable[len(prefix) :].split(";") if "=" in p]
    return []


def _parent_of(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def _bound_folders(pid: int) -> list[str]:
    """The folders a bubblewrap sandbox binds, as its mount namespace lists them (each mount's
    root: the folder's path, the campaign's being on the root filesystem). Not its command
    line: as root, the backend binds them onto a staging folder first
    (evaluator/sandbox/bwrap_backend.py), so bwrap's arguments name only the staging folder."""
    lines = Path(f"/proc/{pid}/mountinfo").read_text().splitlines()
    return [line.split()[3].replace("\\040", " ") for line in lines]


def _kill_if_alive(pid: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)


def _gone_ok(action: Callable[[], object]) -> Callable[[], None]:
    """``action`` on a container, which may have ended and been removed since it was listed."""

    def act() -> None:
        # deferred: each broker, database or daemon client is needed only by its own fault
        import docker.errors

        with contextlib.suppress(docker.errors.NotFound, docker.errors.APIError):
            action()

    return act


def _driver_of(paths: str) -> tuple[str, str]:
    """The worker and submission of the prepared submission a sandbox mounts,
    ``<data>/scratch/<host>-<pid>/submissions/<zip digest>/`` (server/worker/local.py); claims
    name the worker ``<host>:<pid>``. A warm sandbox serves many runs of its submission, so
    this, not a run label, ties it to the scenario it is driving."""
    match = re.search(r"/scratch/([^/\s]+)-(\d+)/submissions/([^/\s]+)/", paths)
    return (f"{match.group(1)}:{match.group(2)}", match.group(3)) if match else ("", "")


# --- the service under test -----------------------------------------------------------------


class Campaign:
    def __init__(self, args: argparse.Namespace, stack: ExitStack) -> None:
        self.args = args
        self.stack = stack
        self.root = shared_dir("arena-faults-")
        stack.callback(shutil.rmtree, self.root, ignore_errors=True)
        self.kind = SandboxKind(args.sandbox)
        self.postgres = PrivatePostgres(self.root, free_port())
        self.redis = PrivateRedis(self.root, free_port())
        self.results: list[FaultResult] = []
        self.submitted: list[int] = []
        self.workers: list[subprocess.Popen] = []
        self.api: subprocess.Popen | None = None
        self.api_url = ""
        self.up: subprocess.Popen | None = None
        self.ledger: Ledger | None = None

    # set-up -----------------------------------------------------------------------------------

    def start_backends(self) -> None:
        self.postgres.init()
        self.stack.callback(self.postgres.stop)
        self.postgres.start()
        self.postgres.create_database("arena")
        self.stack.callback(self.redis.stop)
        self.redis.start()
        upgrade_database(self.postgres.url("arena"))
        self.ledger = Ledger(self.postgres.url("arena"))
        self.suite = cut_suite(SHIPPED_PUBLIC_DIR, self.root / "suite")
        self.paced = self._paced_agent()
        print(
            f"postgres 127.0.0.1:{self.postgres.port}  redis 127.0.0.1:{self.redis.port}  "
            f"sandbox {self.kind.value}  lease {self.args.lease_seconds} s  "
            f"reaper {self.args.reaper_interval_s} s  suite {len(os.listdir(self.suite)) - 1} "
            "scenarios",
            flush=True,
        )

    def settings(self, name: str, **changes: dict) -> Settings:
        """The settings of one machine of the service: its own data folder."""
        folder = self.root / name
        folder.mkdir(mode=0o755, exist_ok=True)
        machine = env_only(
            storage={
                "data_dir": folder,
                "database_url": self.postgres.url("arena"),
                "broker_url": self.redis.url,
                "artifact_store": ArtifactBackend.database,
            },
            suites={"hidden_suite_dir": self.suite, "public_suite_dir": self.suite},
            sandbox={"kind": self.kind},
            service={
                "lease_seconds": self.args.lease_seconds,
                "reaper_interval_s": self.args.reaper_interval_s,
                "daily_quota": 1000,
                "admin_token": "faults-admin",
            },
            evaluation={"jobs": 1},
        )
        return with_fields(machine, **changes)

    def _paced_agent(self) -> Path:
        """keep_lane with a pause per step (same actions, slower scenarios)."""
        folder = self.root / "agents" / "paced_keep_lane"
        shutil.copytree(EXAMPLES / "keep_lane", folder)
        policy = folder / "policy.py"
        policy.write_text(
            policy.read_text()
            + "\n\nimport time as _time\n\n_act = Policy.act\n\n\n"
            + "def _paced(self, obs):\n"
            + f"    _time.sleep({PACE_S})\n"
            + "    return _act(self, obs)\n\n\nPolicy.act = _paced\n"
        )
        return folder

    def start_service(self) -> None:
        """The API and two workers, each with a data folder of its own."""
        with self.ledger.db.session() as session:
            self.token = teams.create_team(session, "fault-team")[1]
        self.workers = [self._worker(1), self._worker(2)]
        port = free_port()
        self.api = start(
            [*ARENA, "serve", "--host", "127.0.0.1", "--port", str(port)],
            environment(self.settings("api")),
            self.root / "api.log",
        )
        self.api_url = f"http://127.0.0.1:{port}"
        if not wait_until(lambda: self.healthy(self.api_url), 60):
            raise RuntimeError(f"the API did not start, see {self.root / 'api.log'}")

    def _worker(self, number: int) -> subprocess.Popen:
        return start_worker(
            self.settings(f"worker{number}"), self.root / f"worker{number}.log", concurrency=1
        )

    @staticmethod
    def healthy(url: str) -> bool:
        try:
            return httpx.get(f"{url}/api/v1/healthz", timeout=2).status_code == 200
        except httpx.HTTPError:
            return False

    def submit(self, url: str, token: str, *agents: Path) -> list[int]:
        """Upload each agent as a team does: the next once the last one's validation is over
        (a team has one validation slot: a second upload meanwhile is refused, 409)."""
        ids = []
        for agent in agents:
            ids.append(upload_folder(url, token, agent, self.root / "zips"))
            if not wait_until(lambda: self.validated(url, token, ids[-1]), VALIDATION_LIMIT_S):
                raise RuntimeError(f"submission {ids[-1]} was not validated in time")
        self.submitted += ids
        return ids

    @staticmethod
    def validated(url: str, token: str, submission_id: int) -> bool:
        try:
            response = httpx.get(
                f"{url}/api/v1/submissions/{submission_id}", headers=bearer(token), timeout=10
            )
        except httpx.HTTPError:
            return False
        return response.status_code == 200 and response.json()["status"] != "validating"

    def wait_held(self, condition: Callable[[Results], bool]) -> Results:
        """The scenarios workers hold, once ``condition`` holds of them."""

        def matching() -> Results | None:
            held = self.ledger.held()
            return held if condition(held) else None

        held = wait_until(matching, 180)
        if held is None:
            raise RuntimeError("no worker took a scenario within 180 s")
        return held

    def wait_submissions(self, ids: list[int], limit_s: float = 600) -> dict:
        def finished():
            states = self.ledger.submissions(ids)
            return states if all(s in FINAL_STATES for s, _ in states.values()) else None

        return wait_until(finished, limit_s) or self.ledger.submissions(ids)

    def record(self, result: FaultResult) -> None:
        self.results.append(result)
        print(result.line(), flush=True)

    # faults of the two-worker service ----------------------------------------------------------

    def worker_sigkill(self) -> FaultResult:
        self.submit(self.api_url, self.token, self.paced, EXAMPLES / "keep_lane")
        victim = self.workers[0]
        name = f"{socket.gethostname()}:{victim.pid}"
        held = self.wait_held(lambda h: any(row.worker == name for row in h.values()))
        lost = {key: row.claims for key, row in held.items() if row.worker == name}
        started = time.monotonic()
        stop(victim, signal.SIGKILL)
        self.workers[0] = self._worker(1)  # restarted, as a supervisor would

        def reclaimed():
            results = self.ledger.results() or {}
            for key, claim in lost.items():
                row = results.get(key)
                if row is not None and row.claims > claim:
                    return f"{key[1]} of run {key[0]} claimed again (claim {row.claims})"
            return None

        found = wait_until(reclaimed, RECOVERY_LIMIT_S)
        return FaultResult(
            "worker_sigkill", _since(started, found), found or "the lost scenario never returned"
        )

    def sandbox_kill(self) -> FaultResult:
        self.submit(self.api_url, self.token, self.paced)

        first_seen: dict[str, float] = {}

        def running():
            """A sandbox alive for a while, of a worker holding one scenario (one job each):
            the sandbox and the scenario its agent is driving."""
            held = self.ledger.held()
            uploads = self.ledger.upload_folders({run_id for run_id, _ in held})
            drivers = {(row.worker, uploads[key[0]]): key for key, row in held.items()}
            for sandbox in campaign_sandboxes(self.root, self.kind):
                seen = first_seen.setdefault(sandbox.key, time.monotonic())
                settled = time.monotonic() - seen > SANDBOX_SETTLE_S
                if sandbox.running and settled and sandbox.driver in drivers:
                    return sandbox, drivers[sandbox.driver]
            return None

        found = wait_until(running, 180)
        if found is None:
            raise RuntimeError("no agent sandbox started within 180 s")
        target, scenario = found
        before = self.ledger.results() or {}
        started = time.monotonic()
        target.kill()
        found = wait_until(lambda: self.ledger.finished_since(before, scenario), RECOVERY_LIMIT_S)
        outcome = f"{found}; the worker went on" if found else "its scenario never finished"
        return FaultResult("sandbox_kill", _since(started, found), outcome)

    def broker_restart(self) -> FaultResult:
        self.submit(self.api_url, self.token, self.paced, EXAMPLES / "random", self.paced)
        self.wait_held(lambda h: len(h) >= 1)
        wait_until(lambda: self.redis.queued() > 0, 30)
        queued = self.redis.queued()
        before = self.ledger.results() or {}
        started = time.monotonic()
        self.redis.stop()
        self.redis.start()
        found = wait_until(lambda: self.ledger.new_claim(before), RECOVERY_LIMIT_S)
        outcome = f"{queued} queued message(s) lost; " + (found or "no scenario claimed again")
        return FaultResult("broker_restart", _since(started, found), outcome)

    def database_restart(self) -> FaultResult:
        self.submit(self.api_url, self.token, self.paced, EXAMPLES / "planner")
        self.wait_held(lambda h: len(h) >= 1)
        before = self.ledger.results() or {}
        started = time.monotonic()
        self.postgres.crash()
        time.sleep(DATABASE_DOWN_S)
        self.postgres.start()

        def resumed():
            if not self.healthy(self.api_url):
                return None
            return self.ledger.new_claim(before) or self.ledger.finished_since(before)

        found = wait_until(resumed, RECOVERY_LIMIT_S)
        outcome = f"down {DATABASE_DOWN_S:.0f} s; " + (found or "no progress after the restart")
        return FaultResult("database_restart", _since(started, found), outcome)

    def stop_service(self) -> None:
        """SIGTERM every service process at once, wait for each, SIGKILL what outlasts
        STOP_LIMIT_S. (`arena up` alone gets the signal: it stops its own children.)"""
        processes = [p for p in (*self.workers, self.api, self.up) if p is not None]
        for process in processes:
            if process.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGTERM)
        for process in processes:
            try:
                process.wait(timeout=STOP_LIMIT_S)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGKILL)
                process.wait()

    # faults of the embedded service (`arena up`) ---------------------------------------------

    def start_up(self) -> None:
        settings = self.settings(
            "up", storage={"artifact_store": ArtifactBackend.folder}, evaluation={"jobs": 2}
        )
        self.up_dir = settings.storage.data_dir
        self.up_port = free_port()
        command = [*ARENA, "up", "--host", "127.0.0.1", "--port", str(self.up_port)]
        self.up = start(command, environment(settings), self.root / "up.log")
        self.up_url = f"http://127.0.0.1:{self.up_port}"
        if not wait_until(lambda: self.healthy(self.up_url), 120):
            raise RuntimeError(f"`arena up` did not start, see {self.root / 'up.log'}")
        self.up_token = (self.up_dir / "demo_token").read_text().strip()

    def embedded_kill(self, sig: signal.Signals) -> FaultResult:
        name = f"embedded_{sig.name.lower()}"
        ids = self.submit(self.up_url, self.up_token, self.paced, EXAMPLES / "planner")
        runs = self._runs_of(ids)
        self.wait_held(lambda h: any(run in runs() for run, _ in h))
        before = self.ledger.results() or {}
        started = time.monotonic()
        self.up.send_signal(sig)  # the `arena up` process alone, as `kill` or the OOM killer
        gone = wait_until(lambda: not self._up_leftovers(), EXIT_LIMIT_S)
        exit_s = time.monotonic() - started
        processes, sandboxes = self._up_leftovers() or ([], [])
        for pid in processes:  # reported, then removed so that the campaign can go on
            os.kill(pid, signal.SIGKILL)
        for sandbox in sandboxes:
            sandbox.remove()
        self.up.wait(timeout=30)
        self.start_up()
        found = wait_until(lambda: self.ledger.new_claim(before), RECOVERY_LIMIT_S)
        outcome = (
            f"service and its children gone in {exit_s:.1f} s"
            if gone
            else f"{len(processes)} process(es) and {len(sandboxes)} sandbox(es) outlived it"
        )
        outcome += "; after the restart " + (found or "no scenario was claimed again")
        return FaultResult(name, _since(started, found), outcome, clean=bool(gone))

    def _runs_of(self, ids: list[int]) -> Callable[[], set[int]]:
        def runs() -> set[int]:
            try:
                with self.ledger.db.session() as session:
                    return set(
                        session.scalars(
                            select(EvaluationRun.id).where(EvaluationRun.submission_id.in_(ids))
                        )
                    )
            except SQLAlchemyError:
                return set()

        return runs

    def _up_leftovers(self) -> tuple[list[int], list[Sandbox]] | None:
        """What of the stopped `arena up` still exists: processes, sandboxes; None: nothing."""
        processes = campaign_processes(self.up_dir)
        if self.up.poll() is None and self.up.pid not in processes:
            processes.append(self.up.pid)
        sandboxes = campaign_sandboxes(self.up_dir, self.kind)
        return (processes, sandboxes) if processes or sandboxes else None

    # the campaign ----------------------------------------------------------------------------

    def run(self) -> None:
        try:
            self.start_backends()
            self.start_service()
            if self.args.smoke:  # the set-up and two uploads of one team, no fault
                self.submit(self.api_url, self.token, self.paced, EXAMPLES / "keep_lane")
                return
            for fault in (
                self.worker_sigkill,
                self.sandbox_kill,
                self.broker_restart,
                self.database_restart,
            ):
                self.record(fault())
            self.wait_submissions(self.submitted)
            self.stop_service()
            self.workers, self.api = [], None
            self.start_up()
            for sig in (signal.SIGTERM, signal.SIGKILL):
                self.record(self.embedded_kill(sig))
            self.wait_submissions(self.submitted)
        finally:
            # Whatever ended the campaign, the service stops before its folders go, and neither
            # the time limit nor a second signal cuts that short.
            signal.alarm(0)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            self.stop_service()

    def report(self) -> str:
        states = self.ledger.submissions(self.submitted) if self.submitted else {}
        named = {
            sid
            for sid, (status, reason) in states.items()
            if status == "scored" or (status == "failed" and reason)
        }
        lost = len(self.submitted) - len(named)
        duplicates, stuck = self.ledger.integrity()
        # Stopped processes' children may take a moment to exit: only what stays is left over.
        wait_until(
            lambda: (
                not campaign_processes(self.root) and not campaign_sandboxes(self.root, self.kind)
            ),
            LEFTOVER_GRACE_S,
        )
        processes = campaign_processes(self.root)
        sandboxes = campaign_sandboxes(self.root, self.kind)
        for pid in processes:
            print(f"leftover process {pid}: {_cmdline(pid)}", flush=True)
        for sandbox in sandboxes:
            state = "running" if sandbox.running else "stopped"
            worker, upload = sandbox.driver
            print(
                f"leftover sandbox {sandbox.key} ({state}) of worker {worker or '?'} "
                f"upload {upload[:12] or '?'}: {sandbox.labels}",
                flush=True,
            )
        counts = {s: sum(1 for v, _ in states.values() if v == s) for s in FINAL_STATES}
        for sid, (status, reason) in sorted(states.items()):
            if status != "scored":
                print(f"submission {sid}: {status} ({reason or 'no reason given'})", flush=True)
        print(
            f"submissions={len(self.submitted)} scored={counts['scored']} "
            f"failed={counts['failed']} leftover_processes={len(processes)} "
            f"leftover_sandboxes={len(sandboxes)}",
            flush=True,
        )
        survived = sum(1 for r in self.results if r.survived)
        recoveries = [r.recovery_s for r in self.results if r.recovery_s is not None]
        max_recovery = max(recoveries, default=0.0)
        # Leftovers are counted on their own: the one that outlived its fault (embedded_*) is
        # not survived already; any other is seen only here, whichever fault made it.
        return (
            f"faults_injected={len(self.results)} survived={survived} lost={lost} "
            f"duplicates={duplicates} stuck={stuck} leftovers={len(processes) + len(sandboxes)} "
            f"max_recovery_s={max_recovery:.1f}"
        )


def _since(started: float, found: object) -> float | None:
    return time.monotonic() - started if found else None


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:160]
    except OSError:
        return "?"


def _on_alarm(signum: int, frame: object) -> None:
    raise CampaignTimeout


def _on_term(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sandbox", choices=["docker", "bubblewrap"], default=None)
    parser.add_argument("--timeout", type=int, default=900, help="[s] the whole campaign")
    parser.add_argument("--lease-seconds", type=int, default=30)
    parser.add_argument("--reaper-interval-s", type=float, default=10.0)
    parser.add_argument("--keep", action="store_true", help="keep the logs and data folder")
    parser.add_argument(
        "--smoke", action="store_true", help="set up the service and upload twice, no fault"
    )
    args = parser.parse_args()
    try:
        args.sandbox = check_service_kind(args.sandbox or "auto", get_settings().sandbox).value
        sandbox = None
    except SandboxUnavailable as error:
        sandbox = f"a sandbox for the service: {error} (scripts/setup.sh --dev sets one up)"
    require(
        sandbox,
        None
        if _postgres_bin()
        else "PostgreSQL's server (initdb, postgres): apt-get install postgresql",
        tool("redis-server", "apt-get install redis-server"),
    )
    signal.signal(signal.SIGALRM, _on_alarm)
    signal.signal(signal.SIGTERM, _on_term)
    signal.alarm(args.timeout)
    started = time.monotonic()
    with ExitStack() as stack:
        campaign = Campaign(args, stack)
        try:
            campaign.run()
        except CampaignTimeout:
            print(f"the campaign ran past --timeout {args.timeout} s; stopping", flush=True)
        except KeyboardInterrupt:
            print("interrupted; stopping", flush=True)
        finally:
            signal.alarm(0)
        if args.smoke:
            summary = f"smoke: set up, {len(campaign.submitted)} uploads of one team validated"
        else:
            summary = campaign.report() if campaign.ledger else "faults_injected=0"
        if args.keep:
            stack.pop_all()
            print(f"kept {campaign.root} (PostgreSQL and Redis stopped)", flush=True)
            campaign.postgres.stop()
            campaign.redis.stop()
    print(f"campaign_s={time.monotonic() - started:.0f}", flush=True)
    print(summary, flush=True)


if __name__ == "__main__":
    main()
