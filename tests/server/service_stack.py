"""A real service stack for end-to-end tests: a small suite of public scenarios, a database, a
broker, an API process and Celery worker processes."""

from __future__ import annotations

import json
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import httpx

from arena.config import Settings
from tests.server.builders import EXAMPLES, bearer
from tests.server.live import ARENA, environment, start

# Where the three example agents differ: planner completes all, keep_lane fails the merge,
# random fails three.
SCENARIOS = (
    "p000_left_turn_t_low",
    "p009_merge_2lane_low",
    "p016_cruise_2lane_low",
    "p023_overtake_2lane_low",
    "p030_replay_cruise",
)
FINISHED = {"scored", "failed", "rejected", "cancelled", "disqualified"}


def shared_dir(prefix: str) -> Path:
    """A folder the sandbox user (uid 65534) may enter, unlike pytest's private tmp_path."""
    path = Path(tempfile.mkdtemp(prefix=prefix))
    path.chmod(0o755)
    return path


def build_small_suite(root: Path) -> Path:
    """The public suite built once, cut down to :data:`SCENARIOS`."""
    full = root / "public-full"
    subprocess.run(
        [*ARENA, "scenarios", "build", "--suite", "public", "--out", str(full)],
        check=True,
        capture_output=True,
    )
    return cut_suite(full, root / "suite")


def cut_suite(full: Path, small: Path) -> Path:
    """A copy of the suite folder ``full`` with only :data:`SCENARIOS`, in ``small``."""
    manifest = json.loads((full / "manifest.json").read_text())
    manifest["scenarios"] = [s for s in manifest["scenarios"] if s["id"] in SCENARIOS]
    assert len(manifest["scenarios"]) == len(SCENARIOS)
    small.mkdir()
    for scenario in SCENARIOS:
        shutil.copytree(full / scenario, small / scenario)
    (small / "manifest.json").write_text(json.dumps(manifest))
    return small


def start_worker(settings: Settings, log_path: Path, concurrency: int = 2) -> subprocess.Popen:
    return start(
        [*ARENA, "worker", "--concurrency", str(concurrency), "--loglevel", "INFO"],
        environment(settings),
        log_path,
    )


def upload_example(url: str, token: str, name: str, zips: Path) -> int:
    return upload_folder(url, token, EXAMPLES / name, zips)


def upload_folder(url: str, token: str, folder: Path, zips: Path) -> int:
    """Pack the agent ``folder`` into ``zips`` and upload it; the submission's id."""
    from submissions.intake import pack_folder

    name = folder.name
    path = pack_folder(folder, zips / f"{name}.zip")
    with path.open("rb") as handle:
        response = httpx.post(
            f"{url}/api/v1/submissions",
            headers=bearer(token),
            data={"track": "freestyle", "method_name": name, "description": f"example {name}"},
            files={"file": (path.name, handle, "application/zip")},
            timeout=120,
        )
    # Received and stored; the worker validates it, then evaluates it.
    assert response.status_code == 202, response.text
    return response.json()["id"]


def wait_finished(url: str, token: str, submission_id: int, timeout_s: float = 240) -> dict:
    deadline = time.monotonic() + timeout_s
    while True:
        body = httpx.get(
            f"{url}/api/v1/submissions/{submission_id}", headers=bearer(token), timeout=10
        ).json()
        if body["status"] in FINISHED:
            return body
        if time.monotonic() > deadline:
            raise AssertionError(f"submission {submission_id} did not finish: {body}")
        time.sleep(1)


__all__ = ["EXAMPLES", "SCENARIOS"]
