"""The API-contract gate: schemathesis against the running service's own ``/openapi.json``, with
a team token and with the admin token, on SQLite and on PostgreSQL; any finding fails.

Each run is bounded (a few examples per operation, a fixed seed, one worker) so the gate takes
seconds per database, not minutes. Requests go to the service on 127.0.0.1 only.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from tests.server.builders import make_team
from tests.server.live import api_server

CONFIG = Path(__file__).with_name("schemathesis.toml")
MAX_EXAMPLES = 15
SEED = 20221128
RUN_TIMEOUT_S = 300


def schemathesis(url: str, token: str, report_dir: Path) -> subprocess.CompletedProcess:
    executable = shutil.which("schemathesis")
    assert executable, "schemathesis is not installed (pip install -e '.[dev]')"
    command = [
        executable,
        "--config-file",
        str(CONFIG),
        "run",
        f"{url}/openapi.json",
        "--header",
        f"Authorization: Bearer {token}",
        "--max-examples",
        str(MAX_EXAMPLES),
        "--seed",
        str(SEED),
        "--workers",
        "1",
        "--generation-database",
        "none",
        "--no-color",
        "--report",
        "junit",
        "--report-dir",
        str(report_dir),
    ]
    return subprocess.run(
        command, capture_output=True, text=True, timeout=RUN_TIMEOUT_S, cwd=report_dir
    )


@pytest.mark.slow
def test_schemathesis_finds_nothing_with_team_and_admin_tokens(settings, db, tmp_path):
    _, team_token = make_team(db, "alpha")
    with api_server(settings, tmp_path / "api.log") as (url, _):
        for who, token in (("team", team_token), ("admin", settings.service.admin_token)):
            report = tmp_path / who
            report.mkdir()
            done = schemathesis(url, token, report)
            summary = done.stdout[-6000:] + done.stderr[-2000:]
            assert done.returncode == 0, f"schemathesis ({who} token) found:\n{summary}"
            assert "generated" in done.stdout, summary  # it did run test cases


@pytest.mark.slow
def test_the_upload_flow_keeps_its_contract(settings, db, tmp_path):
    """The 202 flow, which random forms rarely reach: a real zip answers 202 ``validating`` with
    a ``Location`` whose GET conforms too; a second upload while it validates answers 409; a zip
    whose directory breaks a rule answers 422. Each answer validated against the OpenAPI
    document the service serves."""
    import requests  # schemathesis validates requests' responses (an httpx one's multipart
    import schemathesis  # request body cannot be read back)

    from tests.server.builders import bearer, pack_example

    _, token = make_team(db, "alpha")
    payload = pack_example("keep_lane", tmp_path).read_bytes()
    with api_server(settings, tmp_path / "api.log") as (url, _):
        schema = schemathesis.openapi.from_url(f"{url}/openapi.json")
        upload_op = schema["/api/v1/submissions"]["POST"]
        detail_op = schema["/api/v1/submissions/{submission_id}"]["GET"]

        def send(zip_bytes: bytes) -> requests.Response:
            return requests.post(
                f"{url}/api/v1/submissions",
                headers=bearer(token),
                data={"method_name": "keep lane"},
                files={"file": ("agent.zip", zip_bytes, "application/zip")},
                timeout=60,
            )

        accepted = send(payload)
        assert accepted.status_code == 202 and accepted.json()["status"] == "validating"
        upload_op.validate_response(accepted)
        shown = requests.get(url + accepted.headers["location"], headers=bearer(token), timeout=30)
        assert shown.status_code == 200 and shown.json()["id"] == accepted.json()["id"]
        detail_op.validate_response(shown)
        busy = send(payload)
        assert busy.status_code == 409
        upload_op.validate_response(busy)
        refused = send(b"PK\x05\x06" + b"\0" * 18)  # an empty zip's end record only
        assert refused.status_code in (409, 422)
        upload_op.validate_response(refused)
