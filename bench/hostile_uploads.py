"""The API under hostile uploads, on loopback: its resident memory and ``/leaderboard`` latency.

Starts the API (``arena serve``, one uvicorn process) and one worker (``arena worker``, one job at
a time, validating in the service's sandbox) on a fresh embedded database seeded with a
leaderboard, measures the API idle, then sends three hostile uploads of each kind issue 23 found
(each from its own team, all at once) and measures it again until every one has been refused or
rejected:

- ``nested-zip``: a few MiB holding a 450 MiB nested zip (once +883 MiB of the API, each);
- ``huge-policy``: a 20 MiB ``policy.py`` (once 3.2 GiB and 53 s of the API, stalling it);
- ``fat-wheel``: a requirement whose small wheel unpacks to 1.6 GB (from a local wheel folder);
- ``offline-without-train``: an offline zip with requirements but no ``train.py``;
- ``parallel-quota``: one team's parallel uploads with one try left;
- ``slow-headers``: connections trickling their request headers (slowloris).

First, on the idle service, the **validation-queue fairness** case (issue 40): a team uploads a zip
of one-MiB ``.py`` files (480 of them; 500 once kept a validation busy for its whole 300 s, and
another team's upload waited 299 s behind it), then another team uploads a small good zip; the
figures are how long the other team waited for its verdict and how long the hostile validation
took in all, with the slice after which a validation yields (``ARENA_VALIDATION_SLICE_S``, 5 s
here so that a yield shows) and the hostile team's validation time as charged.

Prints the figures idle and under load side by side with the targets (resident memory under
300 MiB, ``/leaderboard`` p99 under 50 ms); the last line is
``api_rss_mib=<n> leaderboard_p99_ms=<n> hostile_uploads=<n> rejected=<n>
other_team_wait_s=<n> hostile_validation_s=<n>``.

    python bench/hostile_uploads.py [--sandbox docker|bubblewrap] [--timeout 600]
"""

from __future__ import annotations

import argparse
import asyncio
import io
import json
import os
import random
import shutil
import subprocess
import tempfile
import threading
import time
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx

from arena.settings_changes import env_only
from arena.suite import SHIPPED_PUBLIC_DIR
from server.processes import ARENA, free_port, start, stop

TARGET_RSS_MIB = 300.0
TARGET_P99_MS = 50.0
PER_KIND = 3
SLICE_S = 5.0
HOST = "127.0.0.1"
MiB = 1024**2
POLICY = b"class Policy:\n    def act(self, obs):\n        return {}\n"


def stored(name: str) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.external_attr = 0o100644 << 16
    return info


def deflated(name: str) -> zipfile.ZipInfo:
    info = stored(name)
    info.compress_type = zipfile.ZIP_DEFLATED
    return info


def sparse_bytes(size: int, rng: random.Random) -> bytes:
    """Bytes that deflate about 60:1 (under the ratio limit): a random byte every 64."""
    block = bytearray(64 * 1024)
    for position in range(0, len(block), 64):
        block[position] = rng.randrange(1, 256)
    return bytes(block) * (size // len(block))


def nested_zip(path: Path, rng: random.Random) -> Path:
    inner = io.BytesIO()
    with zipfile.ZipFile(inner, "w") as archive:
        archive.writestr(stored("data.bin"), sparse_bytes(450 * MiB, rng))
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr(deflated("policy.py"), POLICY)
        archive.writestr(deflated("data.zip"), inner.getvalue())
    return path


def huge_policy(path: Path, rng: random.Random) -> Path:
    numbers = ",".join(str(rng.randrange(10**6)) for _ in range(3 * 10**6))
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr(deflated("policy.py"), POLICY + f"TABLE = [{numbers}]\n".encode())
    return path


def fat_wheel(folder: Path) -> None:
    """``fatpkg``: 1.6 GB of zeros in a wheel of about 1.6 MB."""
    folder.mkdir(parents=True, exist_ok=True)
    dist = "fatpkg-1.0.dist-info"
    with zipfile.ZipFile(folder / "fatpkg-1.0-py3-none-any.whl", "w") as wheel:
        wheel.writestr(deflated("fatpkg/__init__.py"), b"")
        with wheel.open(deflated("fatpkg/blob.bin"), "w", force_zip64=True) as blob:
            chunk = b"\0" * (64 * MiB)
            for _ in range(1600 * MiB // len(chunk)):
                blob.write(chunk)
        wheel.writestr(
            deflated(f"{dist}/METADATA"), "Metadata-Version: 2.1\nName: fatpkg\nVersion: 1.0\n"
        )
        wheel.writestr(
            deflated(f"{dist}/WHEEL"),
            "Wheel-Version: 1.0\nRoot-Is-Purelib: true\nTag: py3-none-any\n",
        )
        wheel.writestr(deflated(f"{dist}/RECORD"), "")


def many_sources(path: Path, count: int) -> Path:
    """``count`` one-MiB Python files (170,000-odd statements each: deflated, a few KiB) and a
    policy.py without a Policy class: every file is extracted (and once every one was parsed)
    before the rejection."""
    body = (b"x = 0\n" * (MiB // 6))[:MiB]
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr(deflated("policy.py"), b"class Agent:\n    pass\n")
        for k in range(count):
            archive.writestr(deflated(f"lib/m{k:03d}.py"), body)
    return path


def fairness(
    url: str, hostile_token: str, other_token: str, zips: Path, files: int, timeout: float
) -> tuple[float, float, str, str]:
    """(seconds the other team waited for its verdict, seconds the hostile validation took, both
    verdicts): the hostile upload first, the other team's a second later."""
    hostile_zip = many_sources(zips / "many-sources.zip", files)
    good = zips / "good.zip"
    with zipfile.ZipFile(good, "w") as archive:
        archive.writestr(deflated("policy.py"), POLICY)
    started = time.monotonic()
    hostile = upload(url, hostile_token, hostile_zip)
    hostile.raise_for_status()
    time.sleep(1.0)  # the hostile validation has a worker by now
    asked = time.monotonic()
    other = upload(url, other_token, good)
    other.raise_for_status()
    deadline = asked + timeout
    other_verdict = final_status(url, other_token, other.json()["id"], deadline)
    waited = time.monotonic() - asked
    hostile_verdict = final_status(url, hostile_token, hostile.json()["id"], deadline)
    took = time.monotonic() - started
    return waited, took, other_verdict, hostile_verdict


def with_requirements(path: Path, requirement: str) -> Path:
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr(deflated("policy.py"), POLICY)
        archive.writestr(deflated("requirements.txt"), requirement + "\n")
    return path


def seed(database_url: str, teams: int, ranked: int = 200) -> dict[str, str]:
    """A leaderboard of 200 scored submissions, and the hostile teams' tokens."""
    from server.core.db import Database
    from server.core.migrate import upgrade_database
    from server.sample_data import seed_scored
    from server.services import teams as team_service

    upgrade_database(database_url)
    db = Database(database_url)
    rng = random.Random(3)

    def make_team(name: str) -> tuple[int, str]:
        with db.session() as session:
            team, token = team_service.create_team(session, name)
            return team.id, token

    for k in range(ranked):
        team, _ = make_team(f"ranked-{k:03d}")
        metrics = (rng.random(), rng.uniform(200, 800), rng.uniform(0, 2), rng.uniform(0, 0.2))
        seed_scored(db, team, metrics, method_name=f"method {k}")
    tokens = {f"hostile-{k:02d}": make_team(f"hostile-{k:02d}")[1] for k in range(teams)}
    db.dispose()
    return tokens


def validation_used(database_url: str, team_name: str) -> float:
    """Validation time [s] charged today to the team ``team_name``."""
    from server.core.db import Database
    from server.models import Team, utcnow
    from server.services.validation import used_today

    db = Database(database_url)
    try:
        with db.read_session() as session:
            team = session.query(Team).filter(Team.name == team_name).one()
            return used_today(session, team.id, utcnow())
    finally:
        db.dispose()


def wait_up(url: str, process: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + 60
    while True:
        try:
            if httpx.get(f"{url}/api/v1/healthz", timeout=2).status_code in (200, 503):
                return
        except httpx.HTTPError:
            pass
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"the API did not start: {log.read_text()[-2000:]}")
        time.sleep(0.2)


def rss_mib(pid: int) -> float:
    """The resident memory of the API: its process and its children (uvicorn has none)."""
    total = 0
    for candidate in [pid, *children(pid)]:
        try:
            with open(f"/proc/{candidate}/status") as status:
                for line in status:
                    if line.startswith("VmRSS:"):
                        total += int(line.split()[1])
        except FileNotFoundError:
            continue
    return total / 1024


def children(pid: int) -> list[int]:
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as handle:
            return [int(child) for child in handle.read().split()]
    except FileNotFoundError:
        return []


class Probe:
    """The API's resident memory and ``/leaderboard`` latency, sampled until stopped."""

    def __init__(self, url: str, pid: int) -> None:
        self.url, self.pid = url, pid
        self.latencies: list[float] = []
        self.peak_rss = 0.0
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._memory, daemon=True),
            threading.Thread(target=self._leaderboard, daemon=True),
        ]

    def __enter__(self) -> Probe:
        for thread in self._threads:
            thread.start()
        return self

    def __exit__(self, *_) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join()

    def _memory(self) -> None:
        while not self._stop.wait(0.05):
            self.peak_rss = max(self.peak_rss, rss_mib(self.pid))

    def _leaderboard(self) -> None:
        with httpx.Client(timeout=30) as client:
            while not self._stop.is_set():
                sent = time.perf_counter()
                response = client.get(f"{self.url}/api/v1/leaderboard?track=freestyle")
                response.raise_for_status()
                self.latencies.append(time.perf_counter() - sent)
                time.sleep(0.01)

    def p99_ms(self) -> float:
        ordered = sorted(self.latencies)
        return 1000 * ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]


def upload(url: str, token: str, path: Path, track: str = "freestyle") -> httpx.Response:
    with path.open("rb") as handle:
        return httpx.post(
            f"{url}/api/v1/submissions",
            headers={"Authorization": f"Bearer {token}"},
            data={"method_name": path.stem, "track": track},
            files={"file": (path.name, handle, "application/zip")},
            timeout=300,
        )


async def slow_headers(port: int, seconds: float) -> int:
    """One connection trickling its headers a byte a second; 1 when the API cut it off."""
    reader, writer = await asyncio.open_connection(HOST, port)
    request = b"GET /api/v1/leaderboard HTTP/1.1\r\nHost: x\r\nX-Slow: " + b"y" * 1000
    try:
        for byte in request:
            writer.write(bytes([byte]))
            await writer.drain()
            try:
                if await asyncio.wait_for(reader.read(1), timeout=1.0) == b"":
                    return 1
            except TimeoutError:
                pass
            seconds -= 1
            if seconds <= 0:
                return 0
        return 0
    except ConnectionError:
        return 1
    finally:
        writer.close()


def final_status(url: str, token: str, submission_id: int, deadline: float) -> str:
    """``status`` once validated, with the rule a rejection names: ``rejected[policy-class]``."""
    while True:
        body = httpx.get(
            f"{url}/api/v1/submissions/{submission_id}",
            headers={"Authorization": f"Bearer {token}"},
            timeout=30,
        ).json()
        if body["status"] != "validating" or time.monotonic() > deadline:
            rule = body["status_reason"].rpartition("[rule: ")[2].rstrip("]")
            return f"{body['status']}[{rule}]" if rule else body["status"]
        time.sleep(1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sandbox", default="auto", choices=["auto", "docker", "bubblewrap"])
    parser.add_argument("--timeout", type=float, default=600.0, help="for every verdict [s]")
    parser.add_argument("--smoke", action="store_true", help="one upload of each kind")
    args = parser.parse_args()
    per_kind, ranked, idle_s = (1, 20, 1.0) if args.smoke else (PER_KIND, 200, 5.0)
    source_files = 60 if args.smoke else 480

    work = Path(tempfile.mkdtemp(prefix="arena-hostile-"))
    rng = random.Random(23)
    try:
        wheels = work / "wheelhouse"
        fat_wheel(wheels)
        dataset = work / "dataset"
        dataset.mkdir()
        settings = env_only(storage={"data_dir": work / "data"}, service={"admin_token": "bench"})
        env = {k: v for k, v in os.environ.items() if not k.startswith("ARENA_")}
        env |= {
            "ARENA_DATA_DIR": str(settings.storage.data_dir),
            "ARENA_SANDBOX": args.sandbox,
            "ARENA_TRAIN_DATASET_DIR": str(dataset),
            # The requirements come from the local wheel folder: nothing leaves the machine.
            "ARENA_PACKAGE_INDEX": json.dumps([str(wheels)]),
            "ARENA_HTTP_HEADER_TIMEOUT_S": "5",
            "ARENA_VALIDATION_SLICE_S": str(SLICE_S),
            # A suite for the phases to evaluate on (uploads to a phase without one are refused).
            "ARENA_HIDDEN_SUITE_DIR": str(SHIPPED_PUBLIC_DIR),
        }
        zips = work / "zips"
        zips.mkdir()
        payloads = {
            "nested-zip": nested_zip(zips / "nested.zip", rng),
            "huge-policy": huge_policy(zips / "policy.zip", rng),
            "fat-wheel": with_requirements(zips / "wheel.zip", "fatpkg==1.0"),
            "offline-without-train": with_requirements(zips / "offline.zip", "fatpkg==1.0"),
        }
        parallel = with_requirements(zips / "parallel.zip", "fatpkg==1.0")
        seeded = seed(settings.storage.resolved_database_url, per_kind * len(payloads) + 3, ranked)
        tokens = list(seeded.values())
        hostile_team = list(seeded)[-1]  # the first token popped
        port = free_port()
        url = f"http://{HOST}:{port}"
        api = start([*ARENA, "serve", "--host", HOST, "--port", str(port)], env, work / "api.log")
        worker = start([*ARENA, "worker", "--concurrency", "1"], env, work / "worker.log")
        try:
            wait_up(url, api, work / "api.log")
            with Probe(url, api.pid) as idle:
                time.sleep(idle_s)
            # On the idle service: nothing else holds the worker or the queue.
            waited, took, other_verdict, hostile_verdict = fairness(
                url, tokens.pop(), tokens.pop(), zips, source_files, args.timeout
            )
            charged = validation_used(settings.storage.resolved_database_url, hostile_team)
            deadline = time.monotonic() + args.timeout
            sent = refused = 0
            verdicts: list[tuple[str, str]] = []
            with Probe(url, api.pid) as loaded, ThreadPoolExecutor(32) as pool:
                jobs = []
                for kind, path in payloads.items():
                    track = "offline" if kind == "offline-without-train" else "freestyle"
                    for _ in range(per_kind):
                        jobs.append(pool.submit(upload, url, tokens.pop(), path, track))
                quota_token = tokens.pop()
                jobs += [pool.submit(upload, url, quota_token, parallel) for _ in range(per_kind)]
                slow = pool.submit(
                    lambda: asyncio.run(_gather(*(slow_headers(port, 30) for _ in range(per_kind))))
                )
                accepted = []
                kinds = [kind for kind in payloads for _ in range(per_kind)]
                kinds += ["parallel-quota"] * per_kind
                for kind, job in zip(kinds, jobs, strict=True):
                    response = job.result()
                    sent += 1
                    if response.status_code == 202:
                        token = response.request.headers["authorization"][7:]
                        accepted.append((kind, token, response.json()["id"]))
                    else:
                        refused += 1
                        verdicts.append((kind, f"refused {response.status_code}"))
                cut_off = sum(slow.result())
                sent += per_kind
                refused += cut_off
                verdicts += [("slow-headers", "cut off")] * cut_off
                for kind, token, submission_id in accepted:
                    verdicts.append((kind, final_status(url, token, submission_id, deadline)))
        finally:
            stop(worker)
            stop(api)
        validated = [v for _, v in verdicts if not v.startswith(("refused", "cut off"))]
        rejected = refused + sum(v.startswith(("rejected", "failed")) for v in validated)
        print(f"sandbox={args.sandbox} uploads_per_kind={per_kind} kinds={len(payloads) + 2}")
        for kind in [*payloads, "parallel-quota", "slow-headers"]:
            print(f"  {kind}: {', '.join(sorted(v for k, v in verdicts if k == kind))}")
        print(f"refused at once (4xx or cut off): {refused}")
        print(
            f"api_rss_mib idle={idle.peak_rss:.0f} loaded={loaded.peak_rss:.0f} "
            f"(target < {TARGET_RSS_MIB:.0f}, ratio {loaded.peak_rss / TARGET_RSS_MIB:.2f})"
        )
        print(
            f"leaderboard_p99_ms idle={idle.p99_ms():.1f} loaded={loaded.p99_ms():.1f} "
            f"over {len(loaded.latencies)} requests "
            f"(target < {TARGET_P99_MS:.0f}, ratio {loaded.p99_ms() / TARGET_P99_MS:.2f})"
        )
        print(
            f"validation fairness: {source_files} one-MiB .py files ({hostile_verdict}) took "
            f"{took:.1f} s, charged {charged:.1f} s of validation time; the other team's upload "
            f"({other_verdict}) had its verdict after {waited:.1f} s (a validation yields after "
            f"{SLICE_S:g} s to a team that used less)"
        )
        print(
            f"api_rss_mib={loaded.peak_rss:.0f} leaderboard_p99_ms={loaded.p99_ms():.1f} "
            f"hostile_uploads={sent} rejected={rejected} "
            f"other_team_wait_s={waited:.1f} hostile_validation_s={took:.1f}"
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)


async def _gather(*coroutines):
    return await asyncio.gather(*coroutines)


if __name__ == "__main__":
    main()
