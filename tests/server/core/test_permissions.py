"""The service's folders are closed to the agents' uid 65534: a process running as that uid (what
an agent escaping its sandbox would be) lists and reads nothing in them."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from server.core.permissions import AGENT_UID, close_service_folders, close_to_agents


def as_agent(*command: str) -> subprocess.CompletedProcess:
    uid = str(AGENT_UID)
    return subprocess.run(
        ["setpriv", f"--reuid={uid}", f"--regid={uid}", "--clear-groups", *command],
        capture_output=True,
        text=True,
    )


@pytest.fixture
def open_folder():
    """A folder everyone may enter (pytest's own are private to root)."""
    folder = Path(tempfile.mkdtemp(prefix="arena-permissions-"))
    folder.chmod(0o755)
    yield folder
    shutil.rmtree(folder)


@pytest.mark.skipif(os.geteuid() != 0, reason="only root can run a process as uid 65534")
def test_a_closed_folder_is_unreadable_to_the_agents_uid(open_folder):
    data = open_folder / "data"
    data.mkdir(mode=0o755)
    (data / "arena.db").write_text("every team's results")
    (data / "arena.db").chmod(0o644)
    assert as_agent("cat", str(data / "arena.db")).returncode == 0  # open before
    assert close_to_agents(data) is None
    assert data.stat().st_mode & 0o777 == 0o750  # the service's own group still reads it
    assert as_agent("cat", str(data / "arena.db")).returncode != 0
    assert as_agent("ls", str(data)).returncode != 0


def test_a_folder_the_agents_own_is_reported_not_trusted(tmp_path):
    folder = tmp_path / "suite"
    folder.mkdir()
    if os.geteuid() != 0:
        pytest.skip("only root can give a folder to uid 65534")
    os.chown(folder, AGENT_UID, AGENT_UID)
    warnings = close_service_folders(folder, None)
    assert len(warnings) == 1 and "agents' user" in warnings[0]


def test_a_folder_in_the_agents_group_is_reported_not_trusted(tmp_path):
    folder = tmp_path / "data"
    folder.mkdir()
    if os.geteuid() != 0:
        pytest.skip("only root can give a folder to group 65534")
    os.chown(folder, 0, AGENT_UID)
    warnings = close_service_folders(folder)
    assert len(warnings) == 1 and "agents' group" in warnings[0]
