"""Load benchmark of ``GET /api/v1/leaderboard`` on loopback.

Seeds 1,000 scored submissions (200 teams, per-family metrics, per-episode values of 128 scenarios
for the rank ranges) into a fresh embedded database,
starts the API as a real uvicorn process, then drives it for a bounded time from a separate
client process holding several keep-alive connections, and prints requests/s and latency
percentiles next to the targets (1,000 requests/s, p99 under 50 ms).

    python bench/api_load.py [--seconds 10] [--connections 16] [--database-url URL] [--smoke]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import os
import random
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from datetime import timedelta
from pathlib import Path

import numpy as np

from arena.settings_changes import env_only
from evaluator.scoring.simulated import simulated
from server.core.db import Database
from server.core.migrate import upgrade_database
from server.models import utcnow
from server.sample_data import seed_scored
from server.services import teams

SUBMISSIONS = 1000
TEAMS = 200
SCENARIOS = 128
METRIC_NAMES = ("completion", "time", "humanness", "rules")
FAMILIES = ("cruise", "cut_in", "left_turn_t", "merge", "overtake", "replay", "turn_c")
TARGET_RPS = 1000.0
TARGET_P99_MS = 50.0


def seed(database_url: str, rng: random.Random, submissions: int, n_teams: int) -> None:
    upgrade_database(database_url)
    db = Database(database_url)
    start = utcnow() - timedelta(days=10)
    with db.session() as session:
        team_ids = [teams.create_team(session, f"team-{k:03d}")[0].id for k in range(n_teams)]
    draws = np.random.default_rng(rng.randrange(2**32))
    for k in range(submissions):
        # Per-episode values of 128 scenarios (what the rank ranges resample), a third of them
        # reactive with three episodes; the metrics are the ones they give.
        samples = simulated(
            draws, rng.uniform(0, 0.6), scenarios=SCENARIOS, episodes=3, humanness=rng.uniform(0, 2)
        )
        metrics = tuple(float(v) for v in samples.metrics())
        families = {
            family: dict(zip(METRIC_NAMES, (rng.uniform(0, 1) for _ in METRIC_NAMES), strict=True))
            | {"scenarios": 18}
            for family in FAMILIES
        }
        seed_scored(
            db,
            team_ids[k % n_teams],
            metrics,
            created_at=start + timedelta(minutes=k),
            method_name=f"method {k}",
            families=families,
            samples=samples,
        )
    db.dispose()


async def _connection(
    host: str, port: int, until: float, latencies: list[float], at_least_one: bool = False
) -> int:
    reader, writer = await asyncio.open_connection(host, port)
    request = (f"GET /api/v1/leaderboard?track=freestyle HTTP/1.1\r\nHost: {host}\r\n\r\n").encode()
    done = 0
    while time.perf_counter() < until or (at_least_one and not done):
        sent = time.perf_counter()
        writer.write(request)
        head = await reader.readuntil(b"\r\n\r\n")
        status = head[9:12]
        length = 0
        for line in head.split(b"\r\n"):
            if line.lower().startswith(b"content-length:"):
                length = int(line.split(b":")[1])
        await reader.readexactly(length)
        if status != b"200":
            raise RuntimeError(f"HTTP {status.decode()}")
        latencies.append(time.perf_counter() - sent)
        done += 1
    writer.close()
    return done


def _client(host: str, port: int, connections: int, seconds: float, out) -> None:
    async def main() -> tuple[int, float, list[float], float]:
        latencies: list[float] = []
        # Warm-up (not measured): the first request computes and caches the board (its rank
        # ranges resample every entry once); its latency is reported on its own.
        cold: list[float] = []
        await _connection(host, port, time.perf_counter(), cold, at_least_one=True)
        await _connection(host, port, time.perf_counter() + 1.0, [])
        started = time.perf_counter()
        until = started + seconds
        counts = await asyncio.gather(
            *(_connection(host, port, until, latencies) for _ in range(connections))
        )
        return sum(counts), time.perf_counter() - started, latencies, cold[0]

    out.send(asyncio.run(main()))


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _start_api(settings, host: str, port: int, log: Path) -> subprocess.Popen:
    """``arena serve`` (one uvicorn process), configured through the environment."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("ARENA_")}
    env |= {
        "ARENA_DATA_DIR": str(settings.storage.data_dir),
        "ARENA_DATABASE_URL": settings.storage.database_url,
    }
    command = [sys.executable, "-c", "from arena_command import app; app()", "serve"]
    server = subprocess.Popen(
        [*command, "--host", host, "--port", str(port)],
        env=env,
        stdout=log.open("wb"),
        stderr=subprocess.STDOUT,
    )
    deadline = time.monotonic() + 30
    while True:
        try:
            with socket.create_connection((host, port), timeout=1):
                return server
        except OSError:
            if server.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the API did not start: {log.read_text()}") from None
            time.sleep(0.1)


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="measured time (<= 15)")
    parser.add_argument("--connections", type=int, default=16)
    parser.add_argument("--database-url", default="", help="default: a fresh SQLite file")
    parser.add_argument("--smoke", action="store_true", help="20 submissions for 1 s: it runs")
    args = parser.parse_args()
    seconds = min(args.seconds, 15.0)  # with seeding, start-up and warm-up: under 20 s
    submissions, n_teams = SUBMISSIONS, TEAMS
    if args.smoke:
        seconds, submissions, n_teams = 1.0, 20, 5

    workdir = Path(tempfile.mkdtemp(prefix="arena-bench-"))
    try:
        settings = env_only(
            storage={"data_dir": workdir, "database_url": args.database_url},
            service={"admin_token": "bench"},
        )
        seed(settings.storage.resolved_database_url, random.Random(7), submissions, n_teams)
        host, port = "127.0.0.1", _free_port()
        server = _start_api(settings, host, port, workdir / "api.log")
        try:
            receiver, sender = mp.Pipe(duplex=False)
            client = mp.Process(
                target=_client, args=(host, port, args.connections, seconds, sender)
            )
            client.start()
            total, elapsed, latencies, cold = receiver.recv()
            client.join()
        finally:
            server.terminate()
            server.wait(timeout=20)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    rps = total / elapsed
    p50 = percentile(latencies, 0.50) * 1000
    p99 = percentile(latencies, 0.99) * 1000
    print(f"submissions={submissions} teams={n_teams} connections={args.connections}")
    print(f"requests={total} in {elapsed:.1f} s")
    print(f"requests_per_s={rps:.0f} (target {TARGET_RPS:.0f}, ratio {rps / TARGET_RPS:.2f})")
    print(f"p50_ms={p50:.2f} p99_ms={p99:.2f} (target p99 < {TARGET_P99_MS:.0f} ms)")
    print(f"cold_board_ms={cold * 1000:.0f} (first request: ranks {n_teams} entries from scratch)")
    print(f"rps={rps:.0f} p99_ms={p99:.2f}")


if __name__ == "__main__":
    main()
