"""A scenario's parsed static inputs (its road network and recorded traffic), parsed once per
evaluating process and handed to each episode's process pickled.

Parsing them is a large part of an episode's fixed cost (a network about 10 ms, a replay's
trajectories about 30 ms), the same work for every episode of a scenario; unpickling takes a few
milliseconds. The cache is keyed by the files' bytes, so an edited scenario is parsed again, and
it lives in the evaluating process, never on disk, so nothing an agent could write is ever
unpickled. A parse error is not raised here: the episode's process then parses the files itself
and fails as a simulator error, as it always did.
"""

from __future__ import annotations

import hashlib
import pickle
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

from arena.scenario import ReplayTraffic, Scenario, load_scenario
from sim.replay import ReplayTable
from sim.road import RoadNetwork

# Pickled inputs kept per process: a whole hidden suite takes about 70 MB.
CACHE_BYTES = 256 * 2**20


@dataclass(frozen=True)
class ScenarioInputs:
    """What :class:`sim.simulation.Simulation` would otherwise read from the scenario folder."""

    road: RoadNetwork
    replay: ReplayTable | None  # the recording of a replay scenario, every vehicle replayed

    @classmethod
    def parse(cls, scenario_dir: Path, scenario: Scenario) -> ScenarioInputs:
        folder = Path(scenario_dir)
        replay = None
        if isinstance(scenario.traffic, ReplayTraffic):
            replay = ReplayTable(folder / scenario.traffic.trajectories, scenario.step_length)
        return cls(RoadNetwork.load(folder / scenario.map), replay)


class PackedInputsCache:
    """Pickled :class:`ScenarioInputs` by content, least recently used dropped past ``limit``
    bytes. Thread-safe: an evaluation's jobs share it."""

    def __init__(self, limit: int = CACHE_BYTES) -> None:
        self.limit = limit
        self._packed: OrderedDict[str, bytes] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, scenario_dir: Path) -> bytes | None:
        """The pickled inputs of ``scenario_dir``, or None when they cannot be parsed."""
        try:
            scenario = load_scenario(scenario_dir)
            key = _content_key(Path(scenario_dir), scenario)
        except (OSError, ValueError):
            return None
        with self._lock:
            if key in self._packed:
                self._packed.move_to_end(key)
                return self._packed[key]
        try:  # parsed outside the lock: two jobs rarely start the same scenario at once
            packed = pickle.dumps(ScenarioInputs.parse(scenario_dir, scenario), protocol=5)
        except Exception:
            return None
        with self._lock:
            self._packed[key] = packed
            while sum(map(len, self._packed.values())) > self.limit and len(self._packed) > 1:
                self._packed.popitem(last=False)
        return packed


def _content_key(folder: Path, scenario: Scenario) -> str:
    """sha256 of what the inputs are parsed from: the files' bytes and the step length."""
    digest = hashlib.sha256(repr(scenario.step_length).encode())
    files = [scenario.map]
    if isinstance(scenario.traffic, ReplayTraffic):
        files.append(scenario.traffic.trajectories)
    for name in files:
        digest.update(b"\0" + name.encode() + b"\0")
        digest.update((folder / name).read_bytes())
    return digest.hexdigest()


packed_inputs = PackedInputsCache()
