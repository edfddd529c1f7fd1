"""Environments over small scenario folders; every environment's simulator process is closed."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.sim.builders import ScenarioSpec, lane_y, make_scenario, mission, vehicle_xml

PUBLIC = Path(__file__).parents[2] / "scenarios" / "public"


@pytest.fixture
def closing():
    """Register environments to close at the end of the test (their simulator processes)."""
    envs = []
    yield envs.append
    for env in envs:
        env.close()


@pytest.fixture(scope="module")
def short_road(tmp_path_factory) -> Path:
    """An empty straight road, 30 steps long: an agent standing still is truncated."""
    return make_scenario(
        tmp_path_factory.mktemp("short") / "short", ScenarioSpec(max_episode_steps=30)
    )


@pytest.fixture(scope="module")
def car_ahead(tmp_path_factory) -> Path:
    """A car starting from rest 15 m ahead of the ego in its lane."""
    spec = ScenarioSpec(
        missions=(mission(start=(20.0, lane_y(1), 0.0), speed=10.0),),
        vehicles=[vehicle_xml("slow", 37.25, 1, 0.0, vtype="steady")],
    )
    return make_scenario(tmp_path_factory.mktemp("ahead") / "ahead", spec)
