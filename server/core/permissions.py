"""The service's own folders are closed to the uid every agent runs as.

The data folder holds the database, every team's upload and every record; the hidden suite is
the competition's secret. Sandboxes reach neither (they bind only a submission's own folders), so
this is the second wall: were an agent to escape its sandbox as uid 65534, it would still read
none of them. ``arena up`` and every worker close them when they start (docs/deployment.md).
"""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

log = logging.getLogger(__name__)

AGENT_UID = 65534  # the sandboxes' user (evaluator.sandbox: Docker's and bubblewrap's)
PRIVATE_MODE = 0o700


def close_to_agents(folder: Path) -> str | None:
    """Make ``folder`` (created if missing) ours alone, mode 0700; why not, when it cannot be."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    info = folder.stat()
    if info.st_uid == AGENT_UID:
        return f"{folder} belongs to uid {AGENT_UID}, the agents' user: give it to the service's"
    if stat.S_IMODE(info.st_mode) & 0o077:
        try:
            folder.chmod(PRIVATE_MODE)
        except PermissionError:
            return f"{folder} is open to other users and not ours to close (chmod 700 it)"
    if os.geteuid() == AGENT_UID:
        return f"the service runs as uid {AGENT_UID}, the agents' user: run it as another"
    return None


def close_service_folders(*folders: Path | None) -> list[str]:
    """:func:`close_to_agents` for each folder given; the warnings, also logged."""
    warnings = []
    for folder in folders:
        if folder is None:
            continue
        warning = close_to_agents(folder)
        if warning:
            log.warning("%s", warning)
            warnings.append(warning)
    return warnings
