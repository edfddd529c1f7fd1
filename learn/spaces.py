"""Gymnasium spaces of the agent interface. Observations are the fixed-shape arrays of
:mod:`sim.observation_arrays`, the very arrays a policy with ``observation_format: arrays`` gets
in its sandbox."""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from sim.interface import ActionSpace, AgentInterface
from sim.observation_arrays import ObservationLayout
from sim.vehicle.limits import LIMITS


def observation_space(interface: AgentInterface) -> spaces.Dict:
    """The space of the arrays observation for this interface: a Box per leaf of its
    :class:`~sim.observation_arrays.ObservationLayout`, in nested Dicts."""
    tree: dict = {}
    for leaf in ObservationLayout(interface).leaves:
        node = tree
        for key in leaf.path[:-1]:
            node = node.setdefault(key, {})
        node[leaf.path[-1]] = spaces.Box(leaf.low, leaf.high, leaf.shape, np.dtype(leaf.dtype))
    return _dict_space(tree)


def _dict_space(tree: dict) -> spaces.Dict:
    return spaces.Dict(
        {key: _dict_space(sub) if isinstance(sub, dict) else sub for key, sub in tree.items()}
    )


# The environments' default: a random sample of it drives along the lane at some speed, where
# TargetPose (agent.yaml's default: a pose in the map frame) would sample points anywhere in a
# map-sized box. A policy trained with it says `action_space: LaneWithContinuousSpeed` in its
# agent.yaml.
ENV_DEFAULT_ACTION_SPACE = ActionSpace.LaneWithContinuousSpeed.value


def action_space(space: ActionSpace) -> spaces.Box:
    """The Box of one action space, bounded where the simulator clips (``sim/vehicle``)."""
    reach = LIMITS.max_speed * 0.5  # [m] a generous bound on one step's displacement
    bounds = {
        # [x, y, heading, dt]: a map-sized box; the simulator caps the displacement per step.
        ActionSpace.TargetPose: ([-1e5, -1e5, -math.pi, 0.0], [1e5, 1e5, math.pi, 1.0]),
        ActionSpace.RelativeTargetPose: ([-reach, -reach, -math.pi], [reach, reach, math.pi]),
        ActionSpace.Continuous: ([0.0, 0.0, -1.0], [1.0, 1.0, 1.0]),
        ActionSpace.LaneWithContinuousSpeed: ([0.0, -1.0], [LIMITS.max_lane_speed, 1.0]),
    }[space]
    low, high = (np.asarray(b, np.float32) for b in bounds)
    return spaces.Box(low, high, dtype=np.float32)
