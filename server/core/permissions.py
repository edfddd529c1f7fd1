"""The service's own folders are closed to the uid every agent runs as.

The data folder holds the database, every team's upload and every record; the hidden suite is
the competition's secret. Sandboxes reach neither (they bind only a submission's own folders), so
this is the second wall: were an agent to escape its sandbox as uid 65534, it would still read
none of them. ``arena up`` and every worker close them when they start (docs/deployment.md).

Closed means: nothing for other users. The folder's group keeps what it had, so the service's
own processes under another uid (the API of docker-compose.yml, in the group of the root-owned
folders) still read the suites; the agents' group may never be that group.
"""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

log = logging.getLogger(__name__)

AGENT_UID = 65534  # the sandboxes' user and group (evaluator.sandbox: Docker's and bubblewrap's)
OTHERS = 0o007  # the permission bits of every user neither the owner nor in the group


def close_to_agents(folder: Path) -> str | None:
    """Close ``folder`` (created if missing) to every user outside its owner and group; why
    not, when it cannot be."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    info = folder.stat()
    if info.st_uid == AGENT_UID:
        return f"{folder} belongs to uid {AGENT_UID}, the agents' user: give it to the service's"
    if info.st_gid == AGENT_UID:
        return f"{folder} is in group {AGENT_UID}, the agents' group: give it the service's group"
    mode = stat.S_IMODE(info.st_mode)
    if mode & OTHERS:
        try:
            folder.chmod(mode & ~OTHERS)
        except PermissionError:
            return f"{folder} is open to other users and not ours to close (chmod o-rwx it)"
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
