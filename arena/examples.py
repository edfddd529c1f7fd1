"""Where the example agents are: ``examples/``, a folder beside our packages rather than inside
one, because they are the team's code, not ours (docs/architecture.md).

The service runs one of them itself (the reference planner, the expert of the solvability check
and of the public replays), so an installed wheel carries them too: as data files under
``<prefix>/share/driving-arena/examples`` (pyproject.toml). They are found there through the
distribution's own file list, which holds wherever the installer put them (a system, virtual
environment, ``--user`` or ``--prefix`` install alike).
"""

from __future__ import annotations

import functools
from importlib import metadata
from pathlib import Path, PurePosixPath

from arena.errors import ArenaError

DISTRIBUTION = "driving-arena"
INSTALLED_UNDER = ("share", "driving-arena", "examples")
_SOURCE_ROOT = Path(__file__).resolve().parents[1]


class ExamplesMissing(ArenaError, FileNotFoundError):
    """Neither a checkout's ``examples/`` nor an installed copy of it was found."""


@functools.cache
def examples_dir() -> Path:
    """The folder holding one folder per example agent."""
    # A checkout (an editable install runs from one, as the service image does) has its
    # pyproject.toml beside the packages; an installed wheel's site-packages has none.
    if (_SOURCE_ROOT / "pyproject.toml").is_file():
        return _SOURCE_ROOT / "examples"
    try:
        distribution = metadata.distribution(DISTRIBUTION)
    except metadata.PackageNotFoundError as exc:
        raise ExamplesMissing(
            f"{DISTRIBUTION} is not installed and {_SOURCE_ROOT} is no checkout"
        ) from exc
    for file in distribution.files or ():
        parts = PurePosixPath(file).parts
        for start in range(len(parts) - len(INSTALLED_UNDER)):
            if parts[start : start + len(INSTALLED_UNDER)] == INSTALLED_UNDER:
                top = PurePosixPath(*parts[: start + len(INSTALLED_UNDER)])
                return Path(distribution.locate_file(top)).resolve()
    raise ExamplesMissing(f"the installed {DISTRIBUTION} lists no {'/'.join(INSTALLED_UNDER)}")


def example_dir(name: str) -> Path:
    """The folder of the example agent ``name`` (``planner``, ``keep_lane``, ...)."""
    return examples_dir() / name
