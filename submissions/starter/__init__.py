"""`arena init`: copy the starting agent (``policy.py``, ``agent.yaml``, ``test_policy.py``)."""

from __future__ import annotations

import shutil
from pathlib import Path

from arena.errors import ArenaError

STARTER = Path(__file__).resolve().parent
FILES = ("policy.py", "agent.yaml", "test_policy.py")


class FolderNotEmpty(ArenaError):
    """The target folder already holds files (never overwrite a participant's work)."""


def write_starter(folder: Path) -> list[Path]:
    """Write the starting agent into ``folder`` (created; must be empty) and return the files."""
    if folder.exists() and any(folder.iterdir()):
        raise FolderNotEmpty(f"{folder} is not empty")
    folder.mkdir(parents=True, exist_ok=True)
    return [Path(shutil.copyfile(STARTER / name, folder / name)) for name in FILES]
