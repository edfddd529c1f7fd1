"""The production deployment, run end to end: `docker-compose.yml` with three workers.

Builds the images offline (scripts/build_offline_images.py: Debian packages and local wheels,
no registry), runs the project's own docker-compose.yml with an override that only swaps the
image names, scales the workers to three, uploads six submissions (the planner and the PPO
example, three teams) through the API on a loopback port, and checks:

* every submission is scored, with the metrics and per-scenario outcomes `arena evaluate` gives
  for the same agent on the same suite;
* the simulator's compiled core runs in the API's container and in every worker (`arena admin
  status`);
* every agent container the workers started (through the host's Docker socket) has no network;
* no scenario was recorded or simulated twice, and every worker ran part of the episodes;
* `docker-compose stop` leaves no container of the project running and no agent container of
  its workers;
* a second `up` keeps the data (the same submissions, the same scores).

It measures the capacity as CPU time, which the other work on a shared machine does not
inflate: the deployment's (every container of the project and every agent container its workers
started, read from their cgroups while it scores: episodes per core-hour of the whole service),
and each example's alone (`arena evaluate` with one job in the bubblewrap sandbox, in a cgroup of
its own: simulator, agent and CLI start-up). The wall-time figure is printed beside them. The
hidden suite is a cut of the public set placed where the `suites` one-shot looks, so that
one-shot finds it built. Everything is removed at the end (`--keep` leaves the stack up).

    python3 bench/deploy_compose.py [--workers 3] [--tag compose-test] [--keep]

Last line: ``compose_ok=1 workers=3 submissions=6 duplicates=0 episodes_per_core_hour=<n>``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import docker
import httpx
from _prerequisites import require, tool

from arena.settings_changes import env_only
from arena.suite import SHIPPED_PUBLIC_DIR
from evaluator.sandbox.backend import OWNER_LABEL, owner_labels
from submissions.intake import pack_folder

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
AGENTS = ("planner", "ppo")
TEAMS = 3
# A cut of the public set: every kind of scenario the planner and PPO meet (reactive traffic of
# several families, a recorded replay).
SCENARIOS = (
    "p000_left_turn_t_low",
    "p009_merge_2lane_low",
    "p016_cruise_2lane_low",
    "p023_overtake_2lane_low",
    "p030_replay_cruise",
)
UP_TIMEOUT_S = 300
SCORED_TIMEOUT_S = 1800
# [s] One upload's sandboxed validation (its requirements included).
VALIDATION_TIMEOUT_S = 600
CLAIMED = re.compile(r"run (\d+): episode (\d+) of (\S+) claimed \(claim (\d+)\)")
# `arena admin status`'s line when every worker answered with the compiled core.
WORKER_CORES = re.compile(r"simulator core of the workers: compiled \(([^;()]+)\)")


def log(message: str) -> None:
    print(f"deploy-compose: {message}", file=sys.stderr, flush=True)


class Stack:
    """One compose project of docker-compose.yml plus the override, with its own data folder."""

    def __init__(self, root: Path, images: dict[str, str], workers: int) -> None:
        self.root = root
        self.workers = workers
        self.data = root / "data"
        self.port = free_port()
        self.project = f"arena-compose-{os.getpid()}"
        self.override = root / "docker-compose.override.yml"
        self.override.write_text(override(images))
        self.secrets = write_secrets(root / "secrets")
        self.admin_token = (self.secrets / "admin_token").read_text().strip()
        # In a file of its own (--env-file): `docker-compose ... down` by hand finds it too.
        self.env_file = root / "compose.env"
        settings = {
            "ARENA_SECRETS_DIR": str(self.secrets),
            **pinned_images(images["tag"]),
            "ARENA_DATA_DIR": str(self.data),
            "ARENA_PORT": str(self.port),
            "ARENA_PUBLISH_ADDRESS": "127.0.0.1",
            # One scenario at a time per worker: three workers share this machine's cores.
            "ARENA_JOBS": "1",
            "ARENA_DAILY_QUOTA": "10",
        }
        self.env_file.write_text("".join(f"{k}={v}\n" for k, v in settings.items()))
        self.env_file.chmod(0o600)
        # The caller's environment would win over the file.
        self.env = {k: v for k, v in os.environ.items() if k not in settings}
        self.url = f"http://127.0.0.1:{self.port}"

    def compose(self, *arguments: str, check: bool = True, capture: bool = False):
        done = subprocess.run(
            [*self.command(), *arguments], env=self.env, text=True, capture_output=capture
        )
        if check and done.returncode != 0:
            detail = (done.stderr or "")[-4000:] if capture else ""
            raise SystemExit(f"docker-compose {' '.join(arguments)} failed: {detail}")
        return done

    def command(self) -> list[str]:
        command = ["docker-compose", "-p", self.project, "--project-directory", str(REPO)]
        command += ["--env-file", str(self.env_file)]
        return [*command, "-f", str(REPO / "docker-compose.yml"), "-f", str(self.override)]

    def up(self) -> float:
        started = time.monotonic()
        if self.compose("up", "-d", "--scale", f"worker={self.workers}", check=False).returncode:
            self.compose("logs", "--tail", "30", check=False)
            raise SystemExit("docker-compose up failed (the services' logs above)")
        deadline = time.monotonic() + UP_TIMEOUT_S
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"{self.url}/api/v1/healthz", timeout=5).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            time.sleep(1)
        else:
            self.compose("logs", "--tail", "40", check=False)
            raise SystemExit("the API did not answer /healthz")
        self.wait_workers()
        return time.monotonic() - started

    def containers(self, service: str | None = None, running_only: bool = True) -> list:
        filters = {"label": [f"com.docker.compose.project={self.project}"]}
        if service is not None:
            filters["label"].append(f"com.docker.compose.service={service}")
        return docker.from_env().containers.list(all=not running_only, filters=filters)

    def wait_workers(self) -> None:
        """Until there are the wanted workers and every service with a health check (PostgreSQL,
        Redis, the API, each worker: `celery inspect ping`) reports healthy."""
        deadline = time.monotonic() + UP_TIMEOUT_S
        health: dict[str, str] = {}
        while time.monotonic() < deadline:
            containers = self.containers()
            for container in containers:
                container.reload()
            health = {
                c.name: c.attrs["State"]["Health"]["Status"]
                for c in containers
                if "Health" in c.attrs["State"]
            }
            workers = self.containers("worker")
            if len(workers) == self.workers and all(v == "healthy" for v in health.values()):
                return
            time.sleep(2)
        raise SystemExit(f"the services did not all become healthy: {health}")

    def agent_containers(self) -> list:
        """Running agent sandboxes of this deployment's workers (their data folder's label)."""
        label = owner_labels(env_only(storage={"data_dir": self.data}).storage.resolved_data_dir)[
            OWNER_LABEL
        ]
        filters = {"label": f"{OWNER_LABEL}={label}"}
        return docker.from_env().containers.list(filters=filters)

    def exec(self, service: str, *command: str) -> str:
        return self.compose("exec", "-T", service, *command, capture=True).stdout

    def sql(self, query: str) -> list[list[str]]:
        output = self.exec("postgres", "psql", "-U", "arena", "-d", "arena", "-At", "-c", query)
        return [line.split("|") for line in output.splitlines() if line]


def override(images: dict[str, str]) -> str:
    """Only the service image's name changes (built offline, not by `compose build`):
    everything else is the project's docker-compose.yml, PostgreSQL and Redis pinned by digest
    (:func:`pinned_images`)."""
    lines = ["services:"]
    for name in ("migrate", "suites", "api", "worker"):
        lines += [f"  {name}:", f"    image: {images['service']}"]
    return "\n".join(lines) + "\n"


def pinned_images(tag: str) -> dict[str, str]:
    """The offline stand-ins of the pulled images, pinned as docker-compose.yml wants them."""
    done = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "pin_images.py"), "--offline", tag],
        stdout=subprocess.PIPE,
        text=True,
        check=True,
    )
    return dict(line.split("=", 1) for line in done.stdout.split())


def write_secrets(folder: Path) -> Path:
    """The deployment's secret files, made as docs/deployment.md has them made."""
    subprocess.run(
        ["sh", str(REPO / "scripts" / "compose_secrets.sh"), str(folder)],
        stdout=subprocess.DEVNULL,
        check=True,
    )
    return folder


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def build_images(tag: str) -> dict[str, str]:
    done = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "build_offline_images.py"), "--tag", tag],
        stdout=subprocess.PIPE,
        text=True,
        check=True,
    )
    return {"tag": tag, **dict(line.split("=", 1) for line in done.stdout.split())}


def cut_suite(dest: Path) -> Path:
    """The public set cut down to :data:`SCENARIOS`, at ``dest``."""
    manifest = json.loads((SHIPPED_PUBLIC_DIR / "manifest.json").read_text())
    manifest["scenarios"] = [s for s in manifest["scenarios"] if s["id"] in SCENARIOS]
    assert len(manifest["scenarios"]) == len(SCENARIOS)
    dest.mkdir(parents=True)
    for scenario in SCENARIOS:
        shutil.copytree(SHIPPED_PUBLIC_DIR / scenario, dest / scenario)
    (dest / "manifest.json").write_text(json.dumps(manifest))
    for path in [dest, *dest.rglob("*")]:
        path.chmod(0o755 if path.is_dir() else 0o644)
    return dest


CGROUP = Path("/sys/fs/cgroup")


def container_cpu_s(container_id: str) -> float | None:
    """CPU time a container used so far [s], from its cgroup (v1 cpuacct or v2 cpu.stat);
    None when it is gone or the layout is not one we know."""
    v1 = CGROUP / "cpuacct" / "docker" / container_id / "cpuacct.usage"
    v2 = [
        CGROUP / "system.slice" / f"docker-{container_id}.scope" / "cpu.stat",
        CGROUP / "docker" / container_id / "cpu.stat",
    ]
    try:
        if v1.is_file():
            return int(v1.read_text()) / 1e9
        for path in v2:
            if path.is_file():
                stat = dict(line.split() for line in path.read_text().splitlines())
                return int(stat["usage_usec"]) / 1e6
    except (OSError, ValueError, KeyError):
        return None
    return None


class DeploymentCpu:
    """The CPU time the deployment's containers (services, workers and the agents they start)
    used since :meth:`start`: sampled often, so an agent container removed between two samples
    loses at most one interval of its time."""

    def __init__(self, stack: Stack) -> None:
        self.stack = stack
        self.baseline: dict[str, float] = {}
        self.latest: dict[str, float] = {}

    def sample(self) -> None:
        for container in [*self.stack.containers(), *self.stack.agent_containers()]:
            used = container_cpu_s(container.id)
            if used is not None:
                self.latest[container.id] = max(used, self.latest.get(container.id, 0.0))

    def start(self) -> None:
        self.sample()
        self.baseline = dict(self.latest)

    def seconds(self) -> float:
        return sum(used - self.baseline.get(cid, 0.0) for cid, used in self.latest.items())


class CpuGroup:
    """A cgroup of our own that a command and all its descendants run in: their CPU time, even
    of processes nobody waits for (the simulator's forkserver children)."""

    def __init__(self, name: str) -> None:
        v1 = CGROUP / "cpuacct"
        self.v1 = v1.is_dir() and (v1 / "cpuacct.usage").is_file()
        self.path = (v1 if self.v1 else CGROUP) / name
        self.path.mkdir()

    def enter(self) -> None:  # in the child, before exec
        (self.path / "cgroup.procs").write_text(str(os.getpid()))

    def seconds(self) -> float:
        if self.v1:
            return int((self.path / "cpuacct.usage").read_text()) / 1e9
        stat = dict(line.split() for line in (self.path / "cpu.stat").read_text().splitlines())
        return int(stat["usage_usec"]) / 1e6

    def remove(self) -> None:
        for _ in range(50):  # its last processes may take a moment to exit
            try:
                self.path.rmdir()
                return
            except OSError:
                time.sleep(0.2)


def evaluate_locally(agent: str, suite: Path, out: Path) -> tuple[dict, float]:
    """`arena evaluate` of the example on the suite, one job, bubblewrap; (summary, CPU seconds
    of the CLI, its simulator and its agent processes)."""
    group = CpuGroup(f"arena-deploy-bench-{os.getpid()}-{agent}")
    try:
        done = subprocess.run(
            [
                sys.executable,
                "-c",
                "from arena_command import app; app()",
                "evaluate",
                str(EXAMPLES / agent),
                "--suite",
                str(suite),
                "--jobs",
                "1",
                "--sandbox",
                "bubblewrap",
                "--out",
                str(out),
                "--json",
            ],
            capture_output=True,
            text=True,
            env={**os.environ, "ARENA_DATA_DIR": str(out.parent / "local-data")},
            preexec_fn=group.enter,
        )
        cpu = group.seconds()
    finally:
        group.remove()
    if done.returncode not in (0, 1):
        raise SystemExit(f"arena evaluate {agent} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout), cpu


def upload(url: str, token: str, zip_path: Path, agent: str) -> int:
    with zip_path.open("rb") as handle:
        response = httpx.post(
            f"{url}/api/v1/submissions",
            headers={"Authorization": f"Bearer {token}"},
            data={"track": "freestyle", "method_name": agent},
            files={"file": (zip_path.name, handle, "application/zip")},
            timeout=300,
        )
    if response.status_code != 202:
        raise SystemExit(f"upload of {agent} refused: {response.status_code} {response.text}")
    submission_id = response.json()["id"]
    # A team has one upload validating at a time: the next waits for this one's verdict.
    deadline = time.monotonic() + VALIDATION_TIMEOUT_S
    while time.monotonic() < deadline:
        shown = httpx.get(
            f"{url}/api/v1/submissions/{submission_id}",
            headers={"Authorization": f"Bearer {token}"},
            timeout=30,
        ).json()
        if shown["status"] == "rejected":
            raise SystemExit(f"upload of {agent} rejected: {shown['status_reason']}")
        if shown["status"] != "validating":
            return submission_id
        time.sleep(0.5)
    raise SystemExit(f"upload of {agent} still validating after {VALIDATION_TIMEOUT_S} s")


def submission(stack: Stack, submission_id: int) -> dict:
    response = httpx.get(
        f"{stack.url}/api/v1/admin/submissions",
        headers={"Authorization": f"Bearer {stack.admin_token}"},
        timeout=30,
    )
    response.raise_for_status()
    return next(s for s in response.json() if s["id"] == submission_id)


def wait_scored(
    stack: Stack, ids: list[int], networks: dict[str, str], cpu: DeploymentCpu
) -> dict[int, dict]:
    """Until every submission finished; meanwhile the network of every agent container the
    workers started is noted in ``networks`` (name -> network mode) and ``cpu`` sampled."""
    deadline = time.monotonic() + SCORED_TIMEOUT_S
    while time.monotonic() < deadline:
        for container in stack.agent_containers():
            networks[container.name] = container.attrs["HostConfig"]["NetworkMode"]
        found = {i: submission(stack, i) for i in ids}
        finished = {
            i: s for i, s in found.items() if s["status"] in ("scored", "failed", "rejected")
        }
        cpu.sample()
        if len(finished) == len(ids):
            return finished
        time.sleep(1)
    raise SystemExit(f"not every submission finished in {SCORED_TIMEOUT_S} s")


class Checks:
    def __init__(self) -> None:
        self.failures: list[str] = []

    def check(self, ok: bool, what: str) -> None:
        log(("ok   " if ok else "FAIL ") + what)
        if not ok:
            self.failures.append(what)


def prerequisites() -> list[str | None]:
    """What the run needs, checked before minutes of image building: a Docker daemon that
    answers, docker-compose (scripts/setup.sh --dev installs both) and bubblewrap for the
    local side of the comparison."""
    try:
        docker.from_env().ping()
        daemon = None
    except docker.errors.DockerException as error:
        daemon = f"a Docker daemon: {error} (scripts/setup.sh --dev starts one)"
    return [
        daemon,
        tool("docker-compose", "apt-get install docker-compose (or scripts/setup.sh --dev)"),
        tool("bwrap", "apt-get install bubblewrap"),
    ]


def compose_services() -> list[str]:
    """The services of docker-compose.yml as docker-compose reads it, its pinned images given
    placeholders (they are resolved when the images are built)."""
    text = (REPO / "docker-compose.yml").read_text()
    needed = set(re.findall(r"\$\{(\w+):\?", text))
    env = {**os.environ, **{name: f"placeholder-{name.lower()}" for name in needed}}
    done = subprocess.run(
        ["docker-compose", "-f", str(REPO / "docker-compose.yml"), "config", "--services"],
        env=env,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise SystemExit(f"docker-compose cannot read docker-compose.yml: {done.stderr[-2000:]}")
    return done.stdout.split()


def compiled_everywhere(stack: Stack) -> tuple[bool, str]:
    """The simulator's compiled core runs in the image, as an organiser checks it: `arena admin
    status` in the API's container says its own core and each worker's."""
    status = stack.exec("api", "arena", "admin", "status").splitlines()
    cores = [line for line in status if line.startswith("simulator core")]
    workers = [WORKER_CORES.fullmatch(line) for line in cores[1:]]
    ok = (
        cores[:1] == ["simulator core here: compiled"]
        and len(workers) == 1
        and workers[0] is not None
        and len(workers[0].group(1).split(", ")) == stack.workers
    )
    return ok, f"the compiled core in the API's container and every worker ({'; '.join(cores)})"


def same_metrics(service: dict | None, local: dict | None) -> bool:
    if service is None or local is None:
        return service == local
    return all(
        (service[k] is None and local[k] is None)
        or (service[k] is not None and local[k] is not None and abs(service[k] - local[k]) < 1e-9)
        for k in ("completion", "time", "humanness", "rules")
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=3)
    parser.add_argument("--tag", default="compose-test", help="tag of the images built")
    parser.add_argument("--keep", action="store_true", help="leave the stack up at the end")
    parser.add_argument(
        "--smoke", action="store_true", help="the prerequisites and the compose file only"
    )
    arguments = parser.parse_args()
    require(*prerequisites())
    if arguments.smoke:
        services = compose_services()
        log(f"smoke: docker-compose reads docker-compose.yml: {' '.join(services)}")
        return
    checks = Checks()

    images = build_images(arguments.tag)
    root = Path(tempfile.mkdtemp(prefix="arena-compose-"))
    root.chmod(0o755)  # the sandbox user (uid 65534) enters the data folder below
    (root / "data").mkdir(mode=0o755)
    suite = cut_suite(root / "data" / "suites" / "hidden")
    stack = Stack(root, images, arguments.workers)
    try:
        log(f"project {stack.project}, API on {stack.url}, data {stack.data}")
        log(f"up in {stack.up():.0f} s with {arguments.workers} workers")
        checks.check(*compiled_everywhere(stack))
        tokens = [
            stack.exec("api", "arena", "admin", "teams", "create", f"team-{i}").split()[-1]
            for i in range(TEAMS)
        ]
        zips = {agent: pack_folder(EXAMPLES / agent, root / f"{agent}.zip") for agent in AGENTS}
        deployment = DeploymentCpu(stack)
        deployment.start()
        started = time.monotonic()
        uploaded = {
            upload(stack.url, token, zips[agent], agent): agent
            for token in tokens
            for agent in AGENTS
        }
        networks: dict[str, str] = {}
        scored = wait_scored(stack, list(uploaded), networks, deployment)
        wall_s = time.monotonic() - started
        deployment_cpu_s = deployment.seconds()
        checks.check(
            bool(networks) and set(networks.values()) == {"none"},
            f"the workers' agent containers have no network ({len(networks)} seen: "
            f"{Counter(networks.values())})",
        )
        checks.check(
            all(s["status"] == "scored" for s in scored.values()),
            f"all {len(scored)} submissions scored "
            f"({Counter(s['status'] for s in scored.values())})",
        )

        local = {}
        cpu_per_episode = {}
        for agent in AGENTS:
            summary, cpu = evaluate_locally(agent, suite, root / "local" / agent)
            local[agent] = summary
            cpu_per_episode[agent] = cpu / len(summary["scenarios"])
        for sid, agent in uploaded.items():
            checks.check(
                same_metrics(scored[sid]["metrics"], local[agent]["metrics"]),
                f"submission {sid} ({agent}): metrics {scored[sid]['metrics']} == arena "
                f"evaluate's {local[agent]['metrics']}",
            )
        rows = stack.sql(
            "select e.submission_id, r.scenario_id, r.episode, r.status, r.steps "
            "from scenario_results r join evaluation_runs e on e.id = r.run_id"
        )
        for sid, agent in uploaded.items():
            service = sorted((r[1], r[3], int(r[4])) for r in rows if int(r[0]) == sid)
            expected = sorted((s["id"], s["status"], s["steps"]) for s in local[agent]["scenarios"])
            checks.check(service == expected, f"submission {sid}: per-scenario outcomes match")

        claims = []
        per_worker = {}
        for container in stack.containers("worker"):
            found = CLAIMED.findall(container.logs().decode(errors="replace"))
            per_worker[container.name] = len(found)
            claims += [(run, episode, scenario) for run, episode, scenario, _ in found]
        runs = stack.sql("select submission_id, count(*) from evaluation_runs group by 1")
        duplicates = sum(n - 1 for n in Counter(claims).values())
        duplicates += len(rows) - len(uploaded) * len(SCENARIOS)
        duplicates += sum(int(n) - 1 for _, n in runs)
        checks.check(duplicates == 0, f"no scenario simulated or recorded twice ({duplicates})")
        checks.check(
            len(per_worker) == arguments.workers and all(per_worker.values()),
            f"every worker ran episodes: {per_worker}",
        )

        stack.compose("stop")
        running = stack.containers()
        agents = stack.agent_containers()
        checks.check(
            not running and not agents,
            f"stop leaves nothing running ({len(running)} service, {len(agents)} agent containers)",
        )
        stack.up()
        again = {sid: submission(stack, sid) for sid in uploaded}
        checks.check(
            all(
                again[sid]["status"] == "scored"
                and same_metrics(again[sid]["metrics"], scored[sid]["metrics"])
                for sid in uploaded
            ),
            "a second up keeps the data: the same submissions with the same scores",
        )

        episodes = len(rows)
        for agent in AGENTS:
            log(
                f"{agent} (arena evaluate, one job): {cpu_per_episode[agent]:.1f} CPU s per "
                f"episode = {3600 / cpu_per_episode[agent]:.0f} episodes per core-hour"
            )
        # The deployment's own figure: every container's CPU (workers and their simulators,
        # agents, API, PostgreSQL, Redis) while it scored the six submissions.
        deployed = episodes / (deployment_cpu_s / 3600)
        cores = min(os.cpu_count() or 1, arguments.workers)
        log(
            f"deployment: {episodes} episodes, {deployment_cpu_s:.0f} CPU s in all its "
            f"containers = {deployed:.0f} episodes per core-hour; wall time {wall_s:.0f} s on "
            f"{cores} cores = {episodes / (wall_s / 3600) / cores:.0f} per core-hour of wall "
            f"time (load average {os.getloadavg()[0]:.1f}: the machine is shared)"
        )
    finally:
        if arguments.keep:
            log(f"left running: {' '.join(stack.command())}")
        else:
            stack.compose("down", "--volumes", "--remove-orphans", check=False, capture=True)
            for container in stack.agent_containers():
                container.remove(force=True)
            subprocess.run(["rm", "-rf", str(root)], check=False)
    if checks.failures:
        raise SystemExit("compose deployment failed: " + "; ".join(checks.failures))
    print(
        f"compose_ok=1 workers={arguments.workers} submissions={len(uploaded)} "
        f"duplicates={duplicates} episodes_per_core_hour={deployed:.0f}"
    )


if __name__ == "__main__":
    main()
