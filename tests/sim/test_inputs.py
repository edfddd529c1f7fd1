"""A scenario's inputs parsed once and pickled to each episode's process drive exactly as the
files parsed by the episode itself."""

from __future__ import annotations

import os

import pytest

from arena.outcome import DoneReason
from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from sim.inputs import PackedInputsCache, ScenarioInputs, read_inputs
from sim.interface import AgentInterface
from sim.isolation import run_episode_isolated
from tests.sim.agents import cruising_agent
from tests.sim.builders import ScenarioSpec, make_scenario
from tests.sim.test_record_regression import EXPECTED, digests

REPLAY_CSV = "vehicle_id,time,x,y,heading,speed,length,width\n" + "".join(
    f"car,{k / 10:.1f},{30 + k:.3f},-1.600,0.00000,10.000,4.50,1.80\n" for k in range(50)
)


def unpickled_inputs(scenario_dir) -> ScenarioInputs:
    """What an episode's process gets: the inputs parsed elsewhere, through pickle."""
    return read_inputs(PackedInputsCache().open(scenario_dir))


def file_of(fd: int) -> int:
    """The memory file behind descriptor ``fd`` (closed)."""
    try:
        return os.fstat(fd).st_ino
    finally:
        os.close(fd)


@pytest.mark.slow
@pytest.mark.parametrize(
    "scenario_id",
    ["p000_left_turn_t_low", "p029_replay_i80_bubble", "p030_replay_cruise"],
)
def test_unpickled_inputs_give_the_same_record_and_observations(scenario_id, tmp_path):
    inputs = unpickled_inputs(SHIPPED_PUBLIC_DIR / scenario_id)
    assert digests(scenario_id, tmp_path, inputs) == EXPECTED[scenario_id]


def test_the_recording_is_replayed_anew_in_every_episode(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec(trajectories=REPLAY_CSV))
    inputs = ScenarioInputs.parse(folder, load_scenario(folder))
    first = inputs.replay.fresh()
    first.active[:] = False  # handed to SUMO during one episode
    assert inputs.replay.fresh().active.all()
    assert inputs.replay.fresh().motion is inputs.replay.motion  # the recording itself is shared


def test_cache_parses_once_per_content_and_again_after_an_edit(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec(trajectories=REPLAY_CSV))
    cache = PackedInputsCache()
    packed = file_of(cache.open(folder))
    assert file_of(cache.open(folder)) == packed
    (folder / "traffic.csv").write_text(REPLAY_CSV.replace("10.000", "11.000"))
    edited = cache.open(folder)
    assert os.fstat(edited).st_ino != packed
    assert float(read_inputs(edited).replay.motion[0, 0, 3]) == 11.0  # speed at step 0


def test_cached_inputs_cannot_be_written(tmp_path):
    fd = PackedInputsCache().open(make_scenario(tmp_path / "sc", ScenarioSpec()))
    try:
        with pytest.raises(PermissionError):
            os.pwrite(fd, b"x", 0)
    finally:
        os.close(fd)


@pytest.mark.slow
def test_cache_drops_the_least_recently_used_past_its_limit(tmp_path):
    one = make_scenario(tmp_path / "one", ScenarioSpec())
    two = make_scenario(tmp_path / "two", ScenarioSpec(trajectories=REPLAY_CSV))
    fd = PackedInputsCache().open(two)
    size = os.fstat(fd).st_size
    os.close(fd)
    cache = PackedInputsCache(limit=size)
    first = file_of(cache.open(one))
    file_of(cache.open(two))
    assert file_of(cache.open(one)) != first  # parsed again: it had been dropped


@pytest.mark.slow
def test_an_unreadable_network_is_left_to_the_episode_and_is_a_simulator_error(tmp_path):
    folder = make_scenario(tmp_path / "sc", ScenarioSpec())
    scenario = load_scenario(folder)
    (folder / scenario.map).write_text("<net><edge")
    assert PackedInputsCache().open(folder) is None
    result = run_episode_isolated(
        folder, cruising_agent, AgentInterface(), record_path=tmp_path / "r.npz"
    )
    assert result.simulator_error is not None
    assert [a.reason for a in result.agents] == [DoneReason.simulator_error]
