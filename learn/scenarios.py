"""Which scenario folders an environment draws its episodes from."""

from __future__ import annotations

from pathlib import Path

from arena.config import Settings, SuiteSettings, get_settings
from arena.scenario import SCENARIO_FILE, load_scenario
from arena.suite import resolve_suite


def scenario_dirs(
    suite: str | Path = "public",
    scenario: str | Path | None = None,
    *,
    suites: SuiteSettings,
    data_dir: Path,
    agents: tuple[int, int] = (1, 3),
) -> tuple[Path, ...]:
    """The scenario folders of ``suite`` (``public``, a built suite folder, or one scenario's
    folder) whose number of mission agents is within ``agents`` (inclusive), sorted by name.
    ``scenario`` narrows them to one: an id in the suite or a scenario folder. ``suites`` and
    ``data_dir`` locate the suites ``public`` and ``hidden`` name (see
    :func:`arena.suite.resolve_suite`)."""
    if scenario is not None and (Path(scenario) / SCENARIO_FILE).is_file():
        folders = [Path(scenario)]
    else:
        root = resolve_suite(suite, suites, data_dir)
        if (root / SCENARIO_FILE).is_file():
            folders = [root]
        else:
            folders = sorted(p.parent for p in root.glob(f"*/{SCENARIO_FILE}"))
        if scenario is not None:
            folders = [f for f in folders if f.name == str(scenario)]
            if not folders:
                raise ValueError(f"no scenario {scenario!r} in {root}")
    low, high = agents
    chosen = tuple(f for f in folders if low <= len(load_scenario(f).missions) <= high)
    if not chosen:
        raise ValueError(f"no scenario with {low} to {high} mission agents in {suite!r}")
    return chosen


def env_scenario_dirs(
    suite: str | Path,
    scenario: str | Path | None,
    settings: Settings | None,
    agents: tuple[int, int],
) -> tuple[Path, ...]:
    """:func:`scenario_dirs` for an environment built with ``settings``, or without them with
    the process's (``gymnasium.make`` has no other way to hand them over)."""
    settings = settings or get_settings()
    return scenario_dirs(
        suite,
        scenario,
        suites=settings.suites,
        data_dir=settings.storage.resolved_data_dir,
        agents=agents,
    )
