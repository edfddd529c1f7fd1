"""A scenario's parsed static inputs (its road network and recorded traffic), parsed once per
evaluating process and handed to each episode's process pickled.

Parsing them is a large part of an episode's fixed cost (a network about 10 ms, a replay's
trajectories about 10 ms), the same work for every episode of a scenario; unpickling takes a few
milliseconds. The cache is keyed by the files' bytes, so an edited scenario is parsed again. The
pickles are kept in sealed memory files (memfd) whose descriptors reach the episode's process
with its other descriptors: nothing goes through the start-up pipe (a megabyte there held up
every start), nothing is on disk, and nothing can be written to them after the parse. A parse
error is not raised here: the episode's process then parses the files itself and fails as a
simulator error, as it always did.
"""

from __future__ import annotations

import fcntl
import hashlib
import mmap
import os
import pickle
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

from arena.scenario import ReplayTraffic, Scenario, load_scenario
from sim.playback import ReplayTable
from sim.road import RoadNetwork

# Pickled inputs kept per process: a whole hidden suite takes about 70 MB.
CACHE_BYTES = 256 * 2**20
_SEALS = fcntl.F_SEAL_WRITE | fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL


@dataclass(frozen=True)
class ScenarioInputs:
    """What :class:`sim.simulation.Simulation` would otherwise read from the scenario folder."""

    road: RoadNetwork
    replay: ReplayTable | None  # the recording of a replay scenario, every vehicle replayed

    @classmethod
    def parse(cls, scenario_dir: Path, scenario: Scenario) -> ScenarioInputs:
        folder = Path(scenario_dir)
        road = RoadNetwork.load(folder / scenario.map)
        replay = None
        if isinstance(scenario.traffic, ReplayTraffic):
            trajectories = folder / scenario.traffic.trajectories
            replay = ReplayTable(trajectories, scenario.step_length, road)
        return cls(road, replay)


def read_inputs(fd: int) -> ScenarioInputs:
    """The inputs in memory file ``fd`` (from :meth:`PackedInputsCache.open`), which is closed."""
    try:
        with mmap.mmap(fd, 0, prot=mmap.PROT_READ) as packed:
            return pickle.loads(packed)
    finally:
        os.close(fd)


class PackedInputsCache:
    """Sealed memory files of pickled :class:`ScenarioInputs` by content, least recently used
    closed past ``limit`` bytes. Thread-safe: an evaluation's jobs share it."""

    def __init__(self, limit: int = CACHE_BYTES) -> None:
        self.limit = limit
        self._files: OrderedDict[str, tuple[int, int]] = OrderedDict()  # key -> (fd, size)
        self._lock = threading.Lock()

    def open(self, scenario_dir: Path) -> int | None:
        """A new descriptor (the caller closes it) of the memory file holding the inputs of
        ``scenario_dir``, or None when they cannot be parsed (or no memory file can be made:
        out of descriptors)."""
        keyed = self.open_keyed(scenario_dir)
        return keyed[1] if keyed is not None else None

    def open_keyed(self, scenario_dir: Path) -> tuple[str, int] | None:
        """:meth:`open`'s descriptor with the inputs' content key (which names them in a
        process that keeps them parsed, :mod:`sim.episode_workers`)."""
        try:
            return self._open(Path(scenario_dir))
        except OSError:
            return None

    def _open(self, scenario_dir: Path) -> tuple[str, int] | None:
        try:
            scenario = load_scenario(scenario_dir)
            key = _content_key(scenario_dir, scenario)
        except (OSError, ValueError):
            return None
        with self._lock:
            if key in self._files:
                self._files.move_to_end(key)
                return key, os.dup(self._files[key][0])
        try:  # parsed outside the lock: two jobs rarely start the same scenario at once
            packed = pickle.dumps(ScenarioInputs.parse(scenario_dir, scenario), protocol=5)
        except Exception:  # any parse error: the episode meets it again and reports it
            return None
        fd = _sealed_memory_file(packed)
        with self._lock:
            if key in self._files:
                os.close(self._files.pop(key)[0])
            self._files[key] = (fd, len(packed))
            while (
                sum(size for _, size in self._files.values()) > self.limit and len(self._files) > 1
            ):
                os.close(self._files.popitem(last=False)[1][0])
            return key, os.dup(fd)


def _sealed_memory_file(data: bytes) -> int:
    fd = os.memfd_create("scenario-inputs", os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        fcntl.fcntl(fd, fcntl.F_ADD_SEALS, _SEALS)
    except BaseException:
        os.close(fd)
        raise
    return fd


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
