"""A mission (ego) vehicle during an episode: pose, motion history and status."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

from arena.outcome import DoneReason
from arena.scenario import Mission
from sim.geometry import wrap
from sim.vehicle import Pose


class Status(StrEnum):
    waiting = "waiting"  # start delay not over yet
    live = "live"
    done = "done"


@dataclass
class Kinematics:
    """Derivatives of the motion, from pose differences over the step [SI units]."""

    # Plain float pairs: per-step scalar maths is cheaper without numpy.
    velocity: tuple[float, float] = (0.0, 0.0)  # [m/s]
    acceleration: tuple[float, float] = (0.0, 0.0)  # [m/s^2]
    jerk: tuple[float, float] = (0.0, 0.0)  # [m/s^3]
    yaw_rate: float = 0.0  # [rad/s]
    angular_acceleration: float = 0.0  # [rad/s^2]
    angular_jerk: float = 0.0  # [rad/s^3]


@dataclass
class MissionVehicle:
    mission: Mission
    pose: Pose
    status: Status = Status.waiting
    reason: DoneReason | None = None
    done_step: int = 0
    steps: int = 0  # agent-steps driven
    distance_travelled: float = 0.0  # [m]
    still_steps: int = 0  # consecutive steps below the not-moving speed
    kinematics: Kinematics = field(default_factory=Kinematics)
    target_lane: str | None = None  # lane controller memory (LaneWithContinuousSpeed)
    # Observation parts that never change during the episode (sim.observation builds them once).
    constant_observation: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_mission(cls, mission: Mission) -> MissionVehicle:
        x, y, heading = mission.start
        pose = Pose(x, y, wrap(heading), mission.start_speed, 0.0)
        vehicle = cls(mission, pose)
        speed = mission.start_speed
        vehicle.kinematics.velocity = (speed * math.cos(heading), speed * math.sin(heading))
        return vehicle

    @property
    def id(self) -> str:
        return self.mission.agent_id

    def advance(self, new: Pose, dt: float) -> None:
        """Move to ``new`` and update the motion derivatives (finite differences over ``dt``)."""
        k = self.kinematics
        vx, vy = (new.x - self.pose.x) / dt, (new.y - self.pose.y) / dt
        ax, ay = (vx - k.velocity[0]) / dt, (vy - k.velocity[1]) / dt
        yaw_rate = wrap(new.heading - self.pose.heading) / dt
        angular_acceleration = (yaw_rate - k.yaw_rate) / dt
        if self.steps == 0:  # no previous acceleration to difference against
            k.jerk, k.angular_jerk = (0.0, 0.0), 0.0
        else:
            k.jerk = ((ax - k.acceleration[0]) / dt, (ay - k.acceleration[1]) / dt)
            k.angular_jerk = (angular_acceleration - k.angular_acceleration) / dt
        k.velocity, k.acceleration = (vx, vy), (ax, ay)
        k.yaw_rate, k.angular_acceleration = yaw_rate, angular_acceleration
        self.distance_travelled += math.hypot(vx, vy) * dt
        self.pose = new
        self.steps += 1

    def finish(self, reason: DoneReason, step: int) -> None:
        self.status = Status.done
        self.reason = reason
        self.done_step = step
