"""Waypoint paths travel packed (``agent_runtime/packed_waypoints.py``): a policy in any sandbox,
cold or forked, gets the very dicts an in-process policy gets from the same simulation, keys in
the same order; and the runtime's own modules never shadow or replace a submission's."""

from __future__ import annotations

from pathlib import Path

import pytest

from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from evaluator.sandbox import start
from scenarios.experts import PlannerAgent, planner_interface
from sim.simulation import Simulation
from submissions.intake import prepare_submission
from tests.evaluator.sandbox.agents import agent, observation
from tests.evaluator.sandbox.test_warm import zygote
from tests.settings import sandbox_args

# Two agents on a curved merge: paths that cross lane joins and end, lanes of other widths.
SCENARIO = SHIPPED_PUBLIC_DIR / "p012_merge_3lane_curve_mid_2agents"
STEPS = 40
# The modules beside the runtime's main.py (agent_runtime/), which it loads by file.
RUNTIME_MODULES = ("confine", "packed_waypoints", "smarts_compat", "zygote")
# The policy answers with what it got: every path's dicts and each dict's key order.
ECHO = (
    "return {k: {'paths': o['waypoint_paths'],"
    " 'keys': [list(w) for path in o['waypoint_paths'] for w in path]} for k, o in obs.items()}"
)


def echoed(obs: dict[str, dict]) -> dict[str, dict]:
    """What ECHO answers for observations whose paths are dicts, as JSON brings it back."""
    return {
        agent_id: {
            "paths": o["waypoint_paths"],
            "keys": [list(w) for path in o["waypoint_paths"] for w in path],
        }
        for agent_id, o in obs.items()
    }


def episode(packed: bool, actions: list[dict] | None = None) -> tuple[list[dict], list[dict]]:
    """The observations of STEPS steps of SCENARIO and the actions taken: ``actions``, else the
    reference planner's. ``packed``: as the simulator gives them to a sandbox handle."""
    planner = PlannerAgent()
    sim = Simulation(
        load_scenario(SCENARIO), SCENARIO, planner_interface(), packed_waypoints=packed
    )
    seen, taken = [], []
    try:
        obs = sim.reset()
        for step in range(STEPS):
            seen.append(obs)
            taken.append(planner.act(obs) if actions is None else actions[step])
            obs = sim.step(taken[-1])
    finally:
        sim.close()
    return seen, taken


@pytest.fixture(scope="module")
def observations() -> tuple[list[dict], list[dict]]:
    """The same episode's observations, packed and as dicts (one simulation at a time: libsumo
    holds one per process)."""
    plain, actions = episode(packed=False)
    packed, _ = episode(packed=True, actions=actions)
    return packed, plain


def test_the_simulator_packs_paths_only_for_the_sandbox(observations) -> None:
    packed, plain = observations
    assert all(isinstance(o["waypoint_paths"], tuple) for step in packed for o in step.values())
    assert all(isinstance(o["waypoint_paths"], list) for step in plain for o in step.values())
    assert max(len(step) for step in plain) == 2  # the second agent enters on the way


def test_a_sandboxed_policy_gets_the_in_process_dicts(
    any_kind, settings, labels, tmp, observations
) -> None:
    packed, plain = observations
    with start(
        agent(tmp, settings, act=ECHO), kind=any_kind, labels=labels, **sandbox_args(settings)
    ) as handle:
        handle.reset()
        for sent, expected in zip(packed, plain, strict=True):
            assert handle.act(sent) == echoed(expected)


def test_a_forked_policy_gets_the_in_process_dicts(
    kind, settings, labels, tmp, observations
) -> None:
    packed, plain = observations
    with zygote(agent(tmp, settings, act=ECHO), kind, settings, labels) as warm:
        forked = warm.fork(settings.sandbox, {})
        try:
            with forked.start() as handle:
                handle.reset()
                for sent, expected in zip(packed[:10], plain, strict=False):
                    assert handle.act(sent) == echoed(expected)
        finally:
            forked.close()


def test_a_submissions_module_named_like_the_runtimes_own_is_its_own(
    any_kind, settings, labels, tmp: Path
) -> None:
    """The runtime loads modules from beside its main.py (its protocol's packed waypoints, the
    SMARTS converters): a submission with modules of those names imports its own, and the
    runtime still uses its own."""
    source = tmp / "src"
    source.mkdir()
    for name in RUNTIME_MODULES:
        (source / f"{name}.py").write_text(f"WHO = 'the submission: {name}'\n")
    (source / "policy.py").write_text(
        f"import {', '.join(RUNTIME_MODULES)}\n\n"
        "class Policy:\n"
        "    def act(self, obs):\n"
        f"        mine = [m.WHO for m in ({', '.join(RUNTIME_MODULES)})]\n"
        "        return {k: [mine, len(o['waypoint_paths'][0])] for k, o in obs.items()}\n"
    )
    submission = prepare_submission(
        source,
        tmp / "submission",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    sent = observation()
    expected_paths = len(sent["Agent_0"]["waypoint_paths"][0])
    with start(submission, kind=any_kind, labels=labels, **sandbox_args(settings)) as handle:
        handle.reset()
        (answer,) = handle.act(sent).values()
    assert answer == [[f"the submission: {name}" for name in RUNTIME_MODULES], expected_paths]
