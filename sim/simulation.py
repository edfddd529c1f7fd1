"""One episode of a scenario: SUMO traffic (or replay), our mission vehicles, events, observations
and the record. :func:`sim.episode.run_episode` drives it with an agent; tools may use it directly.

Typical use::

    sim = Simulation(scenario, scenario_dir, AgentInterface(), seed=7)
    obs = sim.reset()
    while not sim.done:
        obs = sim.step({agent_id: action for agent_id in obs})
    sim.write_record(path)
    sim.close()

A scene with no mission agents (the scenario recorder) uses :func:`scene_states`.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from arena.outcome import AgentOutcome, DoneReason
from arena.scenario import ReplayTraffic, Scenario, content_hash
from sim.bev import BevRenderer, EgoPose
from sim.bubble import ReactiveBubble
from sim.events import NOT_MOVING_SPEED, NOT_MOVING_STEPS, Events, collisions, is_wrong_way
from sim.events import reached_goal as within_goal
from sim.interface import AgentInterface
from sim.lidar import Lidar
from sim.mission_vehicle import MissionVehicle, Status
from sim.observation import build_observation
from sim.observation_arrays import ObservationLayout
from sim.observation_record import ArraysObservation, ObservationRecord
from sim.playback import ReplayTable
from sim.record import EpisodeRecorder, write_npz
from sim.road import LanePosition, RoadNetwork
from sim.road.centrelines import WaypointArrays, packed
from sim.road.waypoints import (
    path_starts,
    road_waypoints,
    route_ahead,
    split_paths,
    waypoint_arrays,
)
from sim.traffic import MissionsOnlyTraffic, SumoTraffic, Traffic
from sim.triggers import CutInTriggers
from sim.vehicle import DECODERS, ControlContext, InvalidAction, check_action
from sim.vehicle.actions import quote
from sim.vehicle.states import Surroundings, VehicleStates

if TYPE_CHECKING:
    from sim.inputs import ScenarioInputs

# SUMO reports the vehicles around an ego by front-bumper distance: ask a little wider, then
# filter by centre distance ourselves.
CONTEXT_MARGIN = 10.0  # [m]
_AT_REST = Events((), False, False, False, False, False, False, False)


class Simulation:
    """An episode of ``scenario``. Not reusable across processes: libsumo allows one running
    simulation per process, so create, run and :meth:`close` one at a time.

    ``arrays``: observations as :class:`sim.observation_record.ArraysObservation` (each agent's
    record of the interface's arrays layout, written in place and valid until its next
    observation) instead of dicts; the record rows and the episode are the same.
    ``packed_waypoints``: observation dicts whose waypoint paths are packed for the sandbox
    protocol (:mod:`agent_runtime.packed_waypoints`), whose runtime makes them the same dicts.
    """

    def __init__(
        self,
        scenario: Scenario,
        scenario_dir: Path,
        interface: AgentInterface,
        seed: int | None = None,
        *,
        with_missions: bool = True,
        inputs: ScenarioInputs | None = None,
        arrays: bool = False,
        packed_waypoints: bool = False,
    ) -> None:
        self.scenario = scenario
        self.scenario_dir = Path(scenario_dir)
        self.interface = interface
        # SMARTS's paths hold the waypoint level with the vehicle plus `lookahead` more (51 for
        # its default 50); ours hold `waypoints_per_path` in all.
        smarts = interface.observation_format == "smarts2022"
        self._points_per_path = interface.waypoints_per_path + int(smarts)
        self.seed = scenario.seed if seed is None else seed
        self.dt = scenario.step_length
        # Parsed once by the evaluating process when given (sim.inputs), else read here.
        self._inputs = inputs
        self.road = (
            inputs.road
            if inputs is not None
            else RoadNetwork.load(self.scenario_dir / scenario.map)
        )
        self._missions = scenario.missions if with_missions else ()
        self._traffic: Traffic | None = None
        self._replay: ReplayTable | None = None  # replayed traffic outside SUMO
        self._bubble: ReactiveBubble | None = None  # replayed traffic inside SUMO
        self._triggers: CutInTriggers | None = None
        # Present before reset() so that an agent failing at start-up still has outcomes.
        self.vehicles = [MissionVehicle.from_mission(m) for m in self._missions]
        self._lanes: dict[str, LanePosition] = {}
        self._moved_to: dict[str, LanePosition] = {}  # this step's lane, until _lane_of reads it
        self.step_count = 0
        self._mission_ids = {m.agent_id for m in self._missions}
        # Why each agent that sent an invalid action was stopped (agent id -> message).
        self.violations: dict[str, str] = {}
        self.recorder = EpisodeRecorder([m.agent_id for m in self._missions])
        self._bev = BevRenderer(self.road, interface, {m.agent_id: m.route for m in self._missions})
        self._lidar = Lidar(self.road) if interface.lidar_point_cloud else None
        # arrays: observations written straight into records of this layout (ArraysObservation)
        self._layout = ObservationLayout(interface) if arrays else None
        self._records: dict[str, ObservationRecord] = {}
        self._packed_waypoints = packed_waypoints

    # --- lifecycle ---------------------------------------------------------------------------

    def reset(self) -> dict[str, dict | ArraysObservation]:
        """Start the traffic (SUMO unless every other vehicle is replayed outside it) and place the
        vehicles; the observations of agents starting at step 0."""
        self.close()
        sc, folder = self.scenario, self.scenario_dir
        if isinstance(sc.traffic, ReplayTraffic) and sc.traffic.bubble_radius is None:
            self._traffic = MissionsOnlyTraffic()
        else:
            routes = folder / sc.traffic.routes if sc.traffic.kind == "sumo" else None
            self._traffic = SumoTraffic(folder / sc.map, routes, self.seed, self.dt)
        if isinstance(sc.traffic, ReplayTraffic):
            if self._inputs is not None and self._inputs.replay is not None:
                table = self._inputs.replay.fresh()
            else:
                table = ReplayTable(folder / sc.traffic.trajectories, self.dt, self.road)
            if sc.traffic.bubble_radius is None:
                self._replay = table
            else:
                self._bubble = ReactiveBubble(table, sc.traffic.bubble_radius, self.road)
        else:
            self._triggers = CutInTriggers(sc.traffic.triggers)
        self.vehicles = [MissionVehicle.from_mission(m) for m in self._missions]
        self.recorder = EpisodeRecorder([m.agent_id for m in self._missions])
        self.step_count = 0
        self.violations = {}
        self._lanes = {}
        self._moved_to = {}
        self._records = {}
        entering = [v for v in self.vehicles if v.mission.start_step <= 0]
        for v in entering:
            self._enter(v)
        if self._bubble is not None:
            self._bubble.update(self._traffic, 0, [(v.pose.x, v.pose.y) for v in self.live])
        self._traffic.step()
        shared = self._shared_neighbours()
        return {
            v.id: self._observe(v, self._surroundings(v, *shared), self._events_at_rest(v))
            for v in entering
        }

    def close(self) -> None:
        if self._traffic is not None:
            self._traffic.close()
            self._traffic = None

    # --- stepping ----------------------------------------------------------------------------

    def step(self, actions: dict[str, object]) -> dict[str, dict | ArraysObservation]:
        """Apply one action per live agent, advance every vehicle by dt, detect events, record.

        A missing, wrongly shaped, non-finite or out-of-range action ends that agent with
        ``invalid_action``, and so does an action for an agent id the scenario does not have (for
        every live agent: it cannot be told which one was meant); :attr:`violations` keeps why.
        Returns the observations of the agents still live afterwards and, once, the last
        observation of each agent that finished while driving this step (``done`` True).
        """
        traffic = self._traffic
        assert traffic is not None, "reset() first"
        self.step_count += 1
        step = self.step_count
        space = self.interface.action_space
        driven = []
        unknown = sorted(map(str, actions.keys() - self._mission_ids))
        for v in self.live:
            try:
                if unknown:
                    raise InvalidAction(
                        "unknown-agent-id", f"an action for unknown agent id {quote(unknown[0])}"
                    )
                if v.id not in actions:
                    raise InvalidAction("missing-agent-id", f"no action for agent id {v.id!r}")
                action = check_action(actions[v.id], space)
            except InvalidAction as error:
                self.violations[v.id] = f"{v.id}: {error}"
                self._finish(v, DoneReason.invalid_action)
                continue
            ctx = ControlContext(
                self.dt,
                v.mission.vehicle.length,
                self.road,
                v.mission.route,
                v.target_lane,
                self._lanes.get(v.id),  # where the last step (or the entry) left it
            )
            new = DECODERS[space](action, v.pose, ctx)
            v.target_lane = ctx.target_lane
            v.advance(new, self.dt)
            lane = self._moved_to[v.id] = self.road.nearest_lane(new.x, new.y, new.heading)
            traffic.move(v.id, new.x, new.y, new.heading, new.speed, lane)
            driven.append(v)
        entering = [
            v for v in self.vehicles if v.status is Status.waiting and v.mission.start_step <= step
        ]
        for v in entering:
            self._enter(v)
        if self._bubble is not None:
            self._bubble.update(traffic, step, [(v.pose.x, v.pose.y) for v in self.live])
        if self._triggers is not None:
            self._triggers.apply(traffic, self._lanes, self.road)
        traffic.step()
        self._keep_egos_in_sumo()

        shared = self._shared_neighbours()
        surroundings = {v.id: self._surroundings(v, *shared) for v in driven + entering}
        events = {}
        for v in driven:
            events[v.id] = self._detect(v, surroundings[v.id], step)
        for v in driven:
            ev = events[v.id]
            if ev.collisions:
                self._finish(v, DoneReason.collision)
            elif ev.off_road:
                self._finish(v, DoneReason.off_road)
            elif ev.reached_goal:
                self._finish(v, DoneReason.reached_goal)
        if step >= self.scenario.max_episode_steps:
            for v in self.vehicles:
                if v.status is not Status.done:
                    self._finish(v, DoneReason.max_episode_steps)
        obs = {}
        for v in driven:
            # As in SMARTS, an agent that finished this step gets its last observation (its
            # events, done = True); from the next step on it is off the road and in no one's
            # neighbours (``_surroundings`` lists live egos only, SUMO has removed it).
            if v.status is Status.done:
                obs[v.id] = self._observe(v, surroundings[v.id], events[v.id])
        for v in self.live:
            ev = events.get(v.id) or self._events_at_rest(v)
            obs[v.id] = self._observe(v, surroundings[v.id], ev)
        return obs

    def fail(self, reason: DoneReason, agent_ids: list[str] | None = None) -> None:
        """End the given (default: every not yet done) agent with ``reason`` (agent failures)."""
        for v in self.vehicles:
            if v.status is not Status.done and (agent_ids is None or v.id in agent_ids):
                self._finish(v, reason)

    # --- state -------------------------------------------------------------------------------

    @property
    def live(self) -> list[MissionVehicle]:
        return [v for v in self.vehicles if v.status is Status.live]

    @property
    def done(self) -> bool:
        return all(v.status is Status.done for v in self.vehicles) or (
            self.step_count >= self.scenario.max_episode_steps
        )

    @property
    def outcomes(self) -> tuple[AgentOutcome, ...]:
        return tuple(
            AgentOutcome(
                id=v.id,
                reached_goal=v.reason is DoneReason.reached_goal,
                reason=v.reason or DoneReason.max_episode_steps,
                steps=v.steps,
                done_step=v.done_step,
            )
            for v in self.vehicles
        )

    def background_states(self) -> VehicleStates:
        """Every vehicle that is not a mission vehicle, as of the last step (SUMO and replay)."""
        assert self._traffic is not None, "reset() first"
        sumo = self._traffic.all_vehicles()
        return VehicleStates.concat(
            [sumo.without(self._mission_ids), self._replay_states(self.step_count)]
        )

    def write_record(self, path: Path) -> None:
        meta = {
            "scenario_id": self.scenario.id,
            "scenario_hash": content_hash(self.scenario_dir),
            "seed": self.seed,
            "dt": self.dt,
            "max_episode_steps": self.scenario.max_episode_steps,
            "episode_steps": self.step_count,
        }
        missions = tuple(v.mission for v in self.vehicles)
        write_npz(path, self.recorder.arrays(meta, self.outcomes, missions))

    # --- internals ---------------------------------------------------------------------------

    def _enter(self, v: MissionVehicle) -> None:
        m = v.mission
        assert self._traffic is not None
        self._traffic.add_vehicle(
            v.id, list(m.route), m.vehicle.length, m.vehicle.width, m.vehicle.height
        )
        self._traffic.move(v.id, v.pose.x, v.pose.y, v.pose.heading, v.pose.speed)
        self._traffic.watch_around(v.id, self.interface.observation_radius + CONTEXT_MARGIN)
        v.status = Status.live

    def _keep_egos_in_sumo(self) -> None:
        """SUMO retires a vehicle that reaches the end of its route, but a live ego goes where
        its agent drives it: put it back, routed onward from where it is."""
        traffic = self._traffic
        assert traffic is not None
        for v in self.live:
            if not traffic.is_in_network(v.id):
                m = v.mission
                route = route_ahead(self.road, v.pose.x, v.pose.y, v.pose.heading)
                traffic.add_vehicle(v.id, route, m.vehicle.length, m.vehicle.width)
                traffic.move(v.id, v.pose.x, v.pose.y, v.pose.heading, v.pose.speed)
                traffic.watch_around(v.id, self.interface.observation_radius + CONTEXT_MARGIN)

    def _finish(self, v: MissionVehicle, reason: DoneReason) -> None:
        v.finish(reason, self.step_count)
        if self._traffic is not None:  # a done vehicle leaves the road at once
            self._traffic.remove(v.id)

    def _replay_states(self, step: int) -> VehicleStates:
        if self._replay is None:
            return VehicleStates.empty()
        return self._replay.states(step)

    def _shared_neighbours(self) -> tuple[VehicleStates, VehicleStates]:
        """The replayed vehicles outside SUMO and the live mission vehicles (lanes as of the
        last step), made once per step for every ego's neighbours."""
        replay = self._replay_states(self.step_count)
        live = self.live
        if len(live) < 2:  # an ego alone has no other egos around
            return replay, VehicleStates.empty()
        rows = np.array(
            [
                (
                    o.pose.x,
                    o.pose.y,
                    o.pose.heading,
                    o.pose.speed,
                    o.mission.vehicle.length,
                    o.mission.vehicle.width,
                )
                for o in live
            ]
        )
        lanes = [self._lanes[o.id].lane.id if o.id in self._lanes else "" for o in live]
        return replay, VehicleStates.of([o.id for o in live], rows, lanes)

    def _surroundings(
        self, v: MissionVehicle, replay: VehicleStates, egos: VehicleStates
    ) -> Surroundings:
        """Other vehicles within the observation radius of ``v``'s centre, nearest first:
        SUMO's, ``replay``'s and the other live egos of ``egos``."""
        traffic = self._traffic
        assert traffic is not None
        x, y, radius = v.pose.x, v.pose.y, self.interface.observation_radius
        if not (len(replay) or len(egos)):  # SUMO's alone
            return Surroundings(*traffic.vehicles_within(v.id, self._mission_ids, x, y, radius))
        sumo = traffic.vehicles_around(v.id, self._mission_ids)
        others = VehicleStates.concat([sumo, replay, egos.without({v.id})])
        return Surroundings(*others.nearest_first(x, y, radius))

    def _lane_of(self, v: MissionVehicle) -> LanePosition:
        lane = self._moved_to.pop(v.id, None)  # found for SUMO's mapping, at the same pose
        if lane is None:
            lane = self.road.nearest_lane(v.pose.x, v.pose.y, v.pose.heading)
        self._lanes[v.id] = lane
        return lane

    def _detect(self, v: MissionVehicle, around: Surroundings, step: int) -> Events:
        pose, m, near = v.pose, v.mission, around.vehicles
        lane = self._lane_of(v)
        in_junction = lane.lane.is_internal or self.road.in_junction(pose.x, pose.y, lane)
        v.still_steps = v.still_steps + 1 if pose.speed < NOT_MOVING_SPEED else 0
        events = Events(
            collisions=collisions(
                pose.x,
                pose.y,
                pose.heading,
                m.vehicle.length,
                m.vehicle.width,
                near,
                around.distance,
            ),
            off_road=not self.road.is_on_road(pose.x, pose.y, lane),
            off_route=not lane.lane.is_internal and lane.lane.edge_id not in m.route,
            on_shoulder=lane.lane.is_shoulder,
            wrong_way=is_wrong_way(pose.heading, lane, in_junction),
            not_moving=v.still_steps >= NOT_MOVING_STEPS,
            reached_goal=within_goal(pose.x, pose.y, m.goal.position, m.goal.radius),
            reached_max_episode_steps=step >= self.scenario.max_episode_steps,
        )
        vx, vy = v.kinematics.velocity
        self.recorder.add(
            v.id,
            step,
            (  # in STEP_FLOATS order
                pose.x,
                pose.y,
                pose.heading,
                pose.speed,
                float(vx),
                float(vy),
                lane.t,
                lane.lane.width,
                lane.heading,
                lane.lane.speed_limit,
            ),
            lane.lane.id,
            lane.lane.index,
            in_junction,
            (  # in EVENT_FLAGS order
                bool(events.collisions),
                events.off_road,
                events.off_route,
                events.on_shoulder,
                events.wrong_way,
                events.not_moving,
                events.reached_goal,
            ),
            near,
        )
        return events

    def _events_at_rest(self, v: MissionVehicle) -> Events:
        """Events of an agent that has not driven yet (just entered): nothing happened."""
        self._lane_of(v)
        return _AT_REST

    def _observe(
        self, v: MissionVehicle, around: Surroundings, events: Events
    ) -> dict | ArraysObservation:
        lane, near = self._lanes[v.id], around.vehicles
        if self._layout is not None:
            return self._observe_arrays(v, lane, near, events)
        waypoints = self._waypoints(v, lane, self._points_per_path)
        paths = packed(waypoints) if self._packed_waypoints else split_paths(waypoints)
        return build_observation(
            vehicle=v,
            step=self.step_count,
            dt=self.dt,
            lane=lane,
            events=events,
            neighbours=near,
            road=self.road,
            waypoint_paths=paths,
            interface=self.interface,
            rasters=self._rasters(v, near),
            lidar=self._lidar.scan(v.pose.x, v.pose.y, v.pose.heading, near)
            if self._lidar
            else None,
            road_waypoints=(
                road_waypoints(self.road, lane, v.pose.x, v.pose.y, v.mission.route)
                if self.interface.road_waypoints
                else None
            ),
        )

    def _observe_arrays(
        self, v: MissionVehicle, lane: LanePosition, near: VehicleStates, events: Events
    ) -> ArraysObservation:
        assert self._layout is not None
        record = self._records.get(v.id)
        if record is None:
            record = self._records[v.id] = ObservationRecord(self._layout)
        return record.write(
            vehicle=v,
            step=self.step_count,
            dt=self.dt,
            lane=lane,
            events=events,
            neighbours=near,
            road=self.road,
            waypoints=self._waypoints(v, lane, self.interface.waypoints_per_path),
            rasters=self._rasters(v, near),
            done=v.status is Status.done,
        )

    def _waypoints(self, v: MissionVehicle, lane: LanePosition, n: int) -> WaypointArrays:
        """``v``'s waypoint paths of up to ``n`` points, from where it is on ``lane``."""
        route = v.mission.route
        starts = path_starts(
            self.road, lane, v.pose.x, v.pose.y, route, self.interface.max_waypoint_paths
        )
        return waypoint_arrays(self.road, starts, route, n)

    def _rasters(self, v: MissionVehicle, near: VehicleStates) -> dict[str, np.ndarray] | None:
        if not self._bev.names:  # the agent asked for none
            return None
        pose, vehicle = v.pose, v.mission.vehicle
        ego = EgoPose(pose.x, pose.y, pose.heading, vehicle.length, vehicle.width)
        return self._bev.render(v.id, ego, near)


def scene_states(
    scenario: Scenario, scenario_dir: Path, steps: int, seed: int | None = None
) -> Iterator[VehicleStates]:
    """Run ``scenario``'s traffic alone (mission vehicles left out) for ``steps`` steps and yield
    every vehicle's state after each step (SUMO and replay vehicles; centre, heading, speed,
    dimensions, lane). Used to record scenes; runs SUMO in this process."""
    sim = Simulation(scenario, scenario_dir, AgentInterface(), seed, with_missions=False)
    try:
        sim.reset()
        for _ in range(steps):
            sim.step({})
            yield sim.background_states()
    finally:
        sim.close()
