"""Scripted aggressive manoeuvres of background vehicles (cut-ins), from the scenario file."""

from __future__ import annotations

from arena.scenario import LaneChangeTrigger
from sim.road import LanePosition, RoadNetwork
from sim.traffic import SumoTraffic


class CutInTriggers:
    """Each trigger fires once: when its vehicle drives on a lane adjacent to the agent's, on the
    same road, between 0 and ``gap_m`` ahead of the agent, it is forced into the agent's lane
    over ``duration_s`` regardless of safety."""

    def __init__(self, triggers: tuple[LaneChangeTrigger, ...]) -> None:
        self._pending = list(triggers)

    def apply(
        self, traffic: SumoTraffic, lanes: dict[str, LanePosition], road: RoadNetwork
    ) -> None:
        if not self._pending:
            return
        ids = set(traffic.libsumo.vehicle.getIDList())
        for trigger in list(self._pending):
            agent_lane = lanes.get(trigger.agent_id)
            if trigger.vehicle not in ids or agent_lane is None:
                continue
            lane_id, s = traffic.lane_position(trigger.vehicle)
            lane = road.lanes.get(lane_id)
            ego = agent_lane.lane
            if lane is None or lane.edge_id != ego.edge_id or abs(lane.index - ego.index) != 1:
                continue
            centre_s = s - traffic.libsumo.vehicle.getLength(trigger.vehicle) / 2
            if 0.0 <= centre_s - agent_lane.s <= trigger.gap_m:
                traffic.force_lane_change(trigger.vehicle, ego.index, trigger.duration_s)
                self._pending.remove(trigger)
