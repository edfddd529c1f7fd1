"""The production deployment, `docker-compose.yml`, run end to end by `bench/deploy_compose.py`:
offline images, three workers, six submissions through the API, results identical to `arena
evaluate`, a clean stop and data kept across a second `up`.

CI-optional: the first run builds images from Debian packages (minutes of CPU), and it needs
dockerd, debootstrap and docker-compose. Run it with ``ARENA_TEST_COMPOSE=1``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

pytestmark = [
    pytest.mark.compose,
    pytest.mark.slow,
    pytest.mark.docker,
    pytest.mark.timeout(3600),
    pytest.mark.skipif(
        os.environ.get("ARENA_TEST_COMPOSE") != "1",
        reason="builds the deployment's images offline and runs docker-compose for minutes: "
        "set ARENA_TEST_COMPOSE=1 to run it (README, docs/deployment.md)",
    ),
]


def test_the_compose_deployment_scores_six_submissions_on_three_workers():
    done = subprocess.run(
        [sys.executable, str(REPO / "bench" / "deploy_compose.py"), "--workers", "3"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=3500,
    )
    assert done.returncode == 0, done.stderr[-6000:]
    fields = dict(field.split("=") for field in done.stdout.strip().splitlines()[-1].split())
    assert fields["compose_ok"] == "1"
    assert (fields["workers"], fields["submissions"], fields["duplicates"]) == ("3", "6", "0")
    assert int(fields["episodes_per_core_hour"]) > 0
