"""The default training reward, in the spirit of the Driving SMARTS 2022 PPO baseline.

Per agent-step: progress towards the goal, a bonus on reaching it, penalties on collision and
leaving the road (which end the episode) and a small per-step penalty while driving the wrong
way. Pass ``reward_fn=`` to an environment to replace it; it gets the same :class:`RewardInput`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class RewardInput:
    agent_id: str
    previous: dict  # encoded observation the action was chosen on
    current: dict  # encoded observation after the step (terminal observation when done)
    events: dict  # the step's events (``sim.events.Events`` as a dict)
    done_reason: str | None  # set when the agent's episode ended on this step
    terms: dict[str, float]  # the scoring profile's humanness and rules terms of this step


RewardFn = Callable[[RewardInput], float]


@dataclass(frozen=True)
class RewardWeights:
    progress_per_m: float = 0.1  # per metre the straight-line distance to the goal shrinks
    goal: float = 10.0
    collision: float = -10.0
    off_road: float = -10.0
    wrong_way_per_step: float = -0.1


def goal_distance(obs: dict) -> float:
    """Straight-line distance [m] from the ego's centre to its goal. In Python floats: twice a
    step, numpy's per-call overhead on two-element arrays was most of the reward's cost."""
    ego = obs["ego_vehicle_state"]
    goal_x, goal_y = ego["goal_position"].tolist()
    x, y = ego["position"].tolist()[:2]
    return math.hypot(goal_x - x, goal_y - y)


def default_reward(step: RewardInput, weights: RewardWeights = RewardWeights()) -> float:
    """``progress_per_m x progress + goal x reached + collision x collided + off_road x off-road
    + wrong_way_per_step x wrong-way``. Progress is measured towards the goal in a straight line,
    so driving in circles earns nothing."""
    reward = weights.progress_per_m * (goal_distance(step.previous) - goal_distance(step.current))
    events = step.events
    if events.get("reached_goal") or step.done_reason == "reached_goal":
        reward += weights.goal
    if events.get("collisions"):
        reward += weights.collision
    if events.get("off_road"):
        reward += weights.off_road
    if events.get("wrong_way"):
        reward += weights.wrong_way_per_step
    return float(reward)
