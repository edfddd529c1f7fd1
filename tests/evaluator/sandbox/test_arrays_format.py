"""``observation_format: arrays``: the policy gets the arrays of the Gymnasium space through every
sandbox, cold and forked; hostile agents fail as with native observations (``test_hostile.py``
and ``test_warm.py`` run their cases in both formats)."""

from __future__ import annotations

import numpy as np
import pytest

from agent_runtime import main as agent_main
from arena.config import get_settings
from arena.suite import SHIPPED_PUBLIC_DIR as PUBLIC_SUITE
from evaluator.sandbox import start
from evaluator.sandbox.array_frames import ArrayFrames
from sim.interface import AgentInterface
from sim.observation_arrays import ObservationEncoder, ObservationLayout
from submissions.sample import sample_observation
from tests.evaluator.sandbox.agents import agent
from tests.evaluator.sandbox.test_warm import zygote
from tests.settings import evaluate_args, sandbox_args

# Fewer neighbour slots than the sample has neighbours: agent.yaml's count must reach the layout.
AGENT_YAML = "observation_format: arrays\ntop_down_rgb: true\nimg_pixels: 32\nmax_neighbours: 5\n"
INTERFACE = AgentInterface(
    observation_format="arrays", top_down_rgb=True, img_pixels=32, max_neighbours=5
)

# Every agent's arrays must be the layout's, writable, and those of earlier steps unchanged. It
# answers with a few sums of what it got (SUMS), so that the values are checked too.
INIT = "self.shapes = {shapes!r}\nself.kept = []"
CHECKS = """
out = {}
for agent_id, o in obs.items():
    found, stack = {}, [('', o)]
    while stack:
        prefix, node = stack.pop()
        for key, value in node.items():
            if isinstance(value, dict):
                stack.append((prefix + key + '/', value))
                continue
            assert isinstance(value, np.ndarray) and value.flags.writeable, (key, type(value))
            found[prefix + key] = (value.dtype.str, list(value.shape))
    assert found == self.shapes, sorted(set(found.items()) ^ set(self.shapes.items()))
    for array, copy in self.kept:
        assert np.array_equal(array, copy), 'an earlier observation changed'
    self.kept.append((o['waypoint_paths']['pos'], o['waypoint_paths']['pos'].copy()))
    out[agent_id] = SUMS
return out
"""
SUMS = (
    "[o['ego_vehicle_state']['speed'].item(),"
    " float(o['waypoint_paths']['pos'].astype(np.float64).sum()),"
    " float(o['neighborhood_vehicle_states']['mask'].sum()),"
    " float(o['top_down_rgb'].astype(np.float64).sum()),"
    " o['step_count'].item()]"
)


def expected_sums(o: dict) -> list[float]:
    """SUMS of the arrays the training environment would give for ``o``."""
    return eval(SUMS, {"np": np, "o": ObservationEncoder(ObservationLayout(INTERFACE)).encode(o)})


def checking_agent(tmp, settings):
    layout = ObservationLayout(INTERFACE)
    shapes = {"/".join(leaf.path): (leaf.dtype, list(leaf.shape)) for leaf in layout.leaves}
    return agent(
        tmp,
        settings,
        act=CHECKS.replace("SUMS", SUMS),
        init=INIT.format(shapes=shapes),
        agent_yaml=AGENT_YAML,
    )


def steps() -> list[dict]:
    """Two agents, then one of them alone with other neighbours and speed."""
    first = sample_observation(("Agent_0", "Agent_1"), rasters=True, img_pixels=32)
    alone = sample_observation(("Agent_1",), neighbours=3, rasters=True, img_pixels=32)
    second = {"Agent_1": alone["Agent_1"]}
    second["Agent_1"]["ego_vehicle_state"]["speed"] = 4.5
    second["Agent_1"]["top_down_rgb"] = np.full((32, 32, 3), 7, np.uint8)
    return [first, second]


def drive(handle) -> None:
    handle.reset()
    for obs in steps():
        assert handle.act(obs) == {k: expected_sums(o) for k, o in obs.items()}


def test_the_policy_gets_the_layouts_arrays(any_kind, settings, labels, tmp) -> None:
    with start(
        checking_agent(tmp, settings),
        kind=any_kind,
        labels=labels,
        **sandbox_args(settings),
    ) as h:
        drive(h)


def test_a_forked_policy_gets_the_layouts_arrays(any_kind, settings, labels, tmp) -> None:
    with zygote(checking_agent(tmp, settings), any_kind, settings, labels) as warm:
        for _ in range(2):  # a second agent from the same zygote starts from a fresh layout
            forked = warm.fork(settings.sandbox, {})
            try:
                with forked.start() as handle:
                    drive(handle)
            finally:
                forked.close()
            assert warm.wait_ready(30.0)


def test_the_runner_reads_back_what_the_frames_hold() -> None:
    """The runner's decoding against the encoder's, without a sandbox: every leaf, every agent."""
    frames = ArrayFrames(INTERFACE)
    reader = agent_main.ArrayObservations(frames.layout.describe())
    for obs in steps():
        payload = memoryview(b"".join(bytes(part) for part in frames.frame(obs)))
        decoded = reader.decode(payload)
        assert list(decoded) == list(obs)
        for agent_id, o in obs.items():
            assert_holds(decoded[agent_id], o, frames.layout)


def test_records_built_ahead_leave_earlier_steps_alone() -> None:
    """The runner builds the next frame's records after answering (``prepare``): each step
    gets its own frame's values, and the arrays a policy kept from earlier steps stay as they
    were; a frame whose length does not match its records is refused."""
    frames = ArrayFrames(INTERFACE)
    reader = agent_main.ArrayObservations(frames.layout.describe())
    kept = []
    for obs in steps() * 2:
        payload = memoryview(b"".join(bytes(part) for part in frames.frame(obs)))
        decoded = reader.decode(payload)
        reader.prepare()
        kept += [(decoded[agent_id], o) for agent_id, o in obs.items()]
    assert len({id(arrays["waypoint_paths"]["pos"].base) for arrays, _ in kept}) == len(kept)
    for arrays, o in kept:
        assert_holds(arrays, o, frames.layout)
    with pytest.raises(ValueError, match="bytes, not"):
        reader.decode(payload[:-1])


def assert_holds(arrays: dict, o: dict, layout: ObservationLayout) -> None:
    """``arrays`` (the runner's) hold what the encoder makes of the observation dict ``o``."""
    expected = ObservationEncoder(layout).encode(o)
    for leaf in layout.leaves:
        got, want = arrays, expected
        for key in leaf.path:
            got, want = got[key], want[key]
        assert got.dtype == want.dtype and got.shape == want.shape
        np.testing.assert_array_equal(got, want)


POLICY_HEAD = "import numpy as np\n\nclass Policy:\n    def act(self, obs):\n"


@pytest.mark.slow
def test_records_and_scores_do_not_depend_on_the_format(tmp) -> None:
    """The same actions in both formats, on a one-agent and a two-agent scenario (the arrays
    agent also checks its arrays every step): byte-identical records, identical scenario
    results; only the submission's own digest differs in ``summary.json``."""
    from evaluator.runner import EvaluationRequest, evaluate
    from tests.evaluator.runner.conftest import TEST_SANDBOX, write_policy

    scenarios = ["p016_cruise_2lane_low", "p019_cruise_2lane_low_2agents"]
    checks = {
        "native": "",
        "arrays": (
            "        for o in obs.values():\n"
            "            assert o['waypoint_paths']['pos'].shape == (4, 50, 2)\n"
            "            assert o['ego_vehicle_state']['speed'].dtype == np.float32\n"
        ),
    }
    summaries = {}
    for fmt, check in checks.items():
        body = f"{POLICY_HEAD}{check}        return {{k: [8.0, 0] for k in obs}}\n"
        source = write_policy(tmp / f"src-{fmt}", body)
        yaml = source / "agent.yaml"
        yaml.write_text(yaml.read_text() + f"observation_format: {fmt}\n")
        summaries[fmt] = evaluate(
            EvaluationRequest(
                source,
                PUBLIC_SUITE,
                out_dir=tmp / fmt,
                scenario_ids=scenarios,
                sandbox=TEST_SANDBOX,
            ),
            **evaluate_args(get_settings()),
        )
    native, arrays = summaries["native"], summaries["arrays"]
    assert native.complete and not native.uncharged
    reasons = {agent.reason for entry in native.scenarios for agent in entry.agents}
    assert not reasons & {"agent_error", "invalid_action", "agent_exited", "step_timeout"}
    first, second = native.to_dict(), arrays.to_dict()
    assert first.pop("submission") != second.pop("submission")
    # The reproducibility manifest names the submission's digest too; everything else is equal.
    assert first["manifest"].pop("submission") != second["manifest"].pop("submission")
    assert first == second
    for scenario_id in scenarios:
        record = f"records/{scenario_id}.npz"
        assert (tmp / "arrays" / record).read_bytes() == (tmp / "native" / record).read_bytes()
