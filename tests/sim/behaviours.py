"""The behaviour fuzz's agents: legal driving an honest agent may do, however poor. Under any of
them the simulator must end every episode with an outcome (a driving outcome or the step limit),
never with an error of its own (docs/scenarios.md, "When an episode outlives its recording")."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sim.interface import ActionSpace
from sim.vehicle.actions import MAX_ACTION_MAGNITUDE as LARGEST
from sim.vehicle.limits import LIMITS

# One agent's observation and the step number -> its action.
Driver = Callable[[dict, int], list[float]]


@dataclass(frozen=True)
class Behaviour:
    name: str
    space: ActionSpace
    driver: Callable[[int], Driver]  # seed -> a driver (random ones draw from it)


def _lane(speed: float, change: Callable[[int], float] = lambda step: 0.0) -> Callable:
    return lambda seed: lambda obs, step: [speed, change(step)]


def _oscillating(seed: int) -> Driver:
    """Full throttle and full brake in turn, steering swinging from lock to lock."""

    def drive(obs: dict, step: int) -> list[float]:
        pedal = (step // 10) % 2
        return [float(1 - pedal), float(pedal), math.sin(step / 7.0)]

    return drive


def _random_value(rng: np.random.Generator, low: float, high: float) -> float:
    """Mostly within the space's physical range, sometimes far past it (clipped or capped by the
    decoder), sometimes at the largest magnitude an action may hold."""
    draw = rng.random()
    if draw < 0.05:
        return float(rng.choice([-LARGEST, LARGEST]))
    if draw < 0.15:
        return float(rng.uniform(-1000.0, 1000.0))
    return float(rng.uniform(low, high))


def _random(space: ActionSpace) -> Callable[[int], Driver]:
    def make(seed: int) -> Driver:
        rng = np.random.default_rng(seed)

        def drive(obs: dict, step: int) -> list[float]:
            value = lambda low, high: _random_value(rng, low, high)  # noqa: E731
            if space is ActionSpace.TargetPose:
                x, y, _ = obs["ego_vehicle_state"]["position"]
                near = lambda at: min(max(at + value(-3, 3), -LARGEST), LARGEST)  # noqa: E731
                return [near(x), near(y), value(-math.pi, math.pi), 0.1]
            if space is ActionSpace.RelativeTargetPose:
                return [value(-1, 3), value(-1, 1), value(-0.3, 0.3)]
            if space is ActionSpace.Continuous:
                return [value(0, 1), value(0, 1), value(-1, 1)]
            return [value(0, LIMITS.max_lane_speed), float(rng.integers(-1, 2))]

        return drive

    return make


BEHAVIOURS: tuple[Behaviour, ...] = (
    Behaviour("stand-still", ActionSpace.LaneWithContinuousSpeed, _lane(0.0)),
    # Slow enough to outlive every recording while moving.
    Behaviour("creep", ActionSpace.LaneWithContinuousSpeed, _lane(1.0)),
    # Slower than recorded traffic: a hidden bubble replay once outlived its recording at 8 m/s.
    Behaviour("cruise-8", ActionSpace.LaneWithContinuousSpeed, _lane(8.0)),
    Behaviour(
        "lane-changes-full-speed",
        ActionSpace.LaneWithContinuousSpeed,
        _lane(LIMITS.max_lane_speed, lambda step: (1.0, 0.0, -1.0, 0.0)[(step // 15) % 4]),
    ),
    Behaviour("oscillating", ActionSpace.Continuous, _oscillating),
    *(Behaviour(f"random-{space.value}", space, _random(space)) for space in ActionSpace),
)


class BehaviourAgent:
    """Drives every mission vehicle of an episode with one behaviour (the sim.agent protocol)."""

    def __init__(self, behaviour: Behaviour, seed: int) -> None:
        self.behaviour, self.seed = behaviour, seed
        self.step = 0
        self._drive = behaviour.driver(seed)

    def reset(self) -> None:
        self.step = 0
        self._drive = self.behaviour.driver(self.seed)

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        self.step += 1
        return {agent_id: self._drive(o, self.step) for agent_id, o in obs.items()}

    def close(self) -> None:
        pass
