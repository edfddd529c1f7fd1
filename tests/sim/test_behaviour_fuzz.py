"""The behaviour fuzz: legal driving never makes the simulator fail. Every behaviour of
tests/sim/behaviours.py over every scenario of the public suite and of a hidden build
(integration); the fast tier runs a sample that always holds the public bubble replay, whose
recording a slow agent outlives."""

from __future__ import annotations

import zlib
from pathlib import Path

import pytest

from arena.outcome import DoneReason
from scenarios.suites import SUITES
from sim.episode import run_episode
from sim.interface import AgentInterface
from tests.sim.behaviours import BEHAVIOURS, Behaviour, BehaviourAgent

PUBLIC = Path(__file__).resolve().parents[2] / "scenarios" / "public"
# What legal driving may end in: the rest (agent failures, invalid actions) would be the
# behaviour's bug, and an exception out of run_episode the simulator's.
DRIVING_ENDS = {
    DoneReason.reached_goal,
    DoneReason.collision,
    DoneReason.off_road,
    DoneReason.max_episode_steps,
}
# Fast tier: the bubble replay whose recording a standing ego outlives, plus a few others.
FAST_SAMPLE = (
    "p029_replay_i80_bubble",
    "p013_merge_3lane_shoulder_low",
    "p021_cut_in_3lane_mid",
    "p033_replay_merge_2agents",
)


def _scenarios(suite: Path) -> list[Path]:
    return sorted(p.parent for p in suite.glob("*/scenario.json"))


def drive_every_behaviour(folder: Path, tmp_path: Path) -> None:
    """Each behaviour over ``folder``: an exception is a simulator failure on legal actions."""
    for behaviour in BEHAVIOURS:
        _drive(folder, behaviour, tmp_path)


def _drive(folder: Path, behaviour: Behaviour, tmp_path: Path) -> None:
    seed = zlib.crc32(f"{folder.name}/{behaviour.name}".encode())
    agent = BehaviourAgent(behaviour, seed)
    try:
        result = run_episode(
            folder,
            agent,
            AgentInterface(action_space=behaviour.space),
            record_path=tmp_path / f"{folder.name}-{behaviour.name}.npz",
        )
    except Exception as error:
        raise AssertionError(
            f"{folder.name} under {behaviour.name} (seed {seed}): the simulator failed on legal "
            f"actions: {error!r}"
        ) from error
    ends = {o.reason for o in result.agents}
    assert ends <= DRIVING_ENDS, (folder.name, behaviour.name, ends, result.detail)


@pytest.mark.parametrize("name", FAST_SAMPLE)
def test_legal_driving_never_fails_the_simulator_sample(name, tmp_path):
    drive_every_behaviour(PUBLIC / name, tmp_path)


def test_a_standing_ego_outlives_the_bubble_recording(tmp_path):
    """The reported case: at speed 0 the episode runs past the last recorded frame; the
    replayed vehicles leave at their last frame, the handed-over ones drive on."""
    folder = PUBLIC / "p029_replay_i80_bubble"
    stand_still = next(b for b in BEHAVIOURS if b.name == "stand-still")
    result = run_episode(
        folder,
        BehaviourAgent(stand_still, 0),
        AgentInterface(action_space=stand_still.space),
        record_path=tmp_path / "record.npz",
    )
    (outcome,) = result.agents
    assert outcome.reason is DoneReason.max_episode_steps
    assert result.steps == 800  # the recording holds 381 steps


@pytest.mark.slow
@pytest.mark.parametrize("name", [p.name for p in _scenarios(PUBLIC)])
def test_legal_driving_never_fails_the_simulator_public(name, tmp_path):
    drive_every_behaviour(PUBLIC / name, tmp_path)


@pytest.mark.parametrize("index", range(len(SUITES["hidden"]())))
def test_legal_driving_never_fails_the_simulator_hidden(hidden_dev, index, tmp_path):
    drive_every_behaviour(_scenarios(hidden_dev)[index], tmp_path)
