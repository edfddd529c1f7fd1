"""The offline_bc example: trained in the sandbox on a tiny dataset of real replays, then
evaluated with its trained output exactly as `arena train` + `arena evaluate --model` do."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from arena.config import SandboxKind, get_settings
from arena.examples import example_dir
from arena.suite import SHIPPED_PUBLIC_DIR
from evaluator.runner import EvaluationRequest, evaluate
from evaluator.training import train
from scenarios.dataset import features as dataset_features
from scenarios.dataset.build import TRANSITIONS, write_transitions
from scenarios.dataset.collect import collect
from submissions.intake import prepare_submission
from tests.evaluator.sandbox.conftest import usable
from tests.settings import env_only, evaluate_args, sandbox_args

EXAMPLE = example_dir("offline_bc")
REPLAY = "p033_replay_merge_2agents"
SCENARIO = "p016_cruise_2lane_low"


def test_its_features_are_the_datasets():
    """A copy (the sandbox cannot import the project), kept identical."""
    shipped = (EXAMPLE / "features.py").read_text()
    assert shipped == Path(dataset_features.__file__).read_text()


@pytest.fixture
def dataset(tmp_path) -> Path:
    folder = tmp_path / "dataset"
    folder.mkdir()
    write_transitions(folder / TRANSITIONS, collect(SHIPPED_PUBLIC_DIR / REPLAY)[0])
    return folder


def test_each_seed_trains_another_model_and_a_seed_the_same_one_again(tmp_path):
    """It once hard-coded SEED = 0: two seeds of a phase trained one model, and the page showed
    a spread of 0. ARENA_TRAIN_SEED seeds its weights and batch order."""
    dataset = tmp_path / "dataset"
    dataset.mkdir()
    rng = np.random.default_rng(0)  # the arrays train.py reads, of a few hundred transitions
    np.savez(
        dataset / TRANSITIONS,
        observations=rng.normal(size=(300, 8)).astype(np.float32),
        actions=rng.normal(size=(300, 3)).astype(np.float32),
        episode=np.repeat(np.arange(3), 100),
    )

    def weights(seed: int, name: str) -> dict[str, np.ndarray]:
        out = tmp_path / name
        out.mkdir()
        env = {
            **os.environ,
            "ARENA_DATASET_DIR": str(dataset),
            "ARENA_MODEL_DIR": str(out),
            "ARENA_TRAIN_SEED": str(seed),
            "BC_EPOCHS": "1",
        }
        subprocess.run([sys.executable, EXAMPLE / "train.py"], env=env, check=True, timeout=120)
        return dict(np.load(out / "weights.npz"))

    first, again, other = weights(0, "a"), weights(0, "b"), weights(1, "c")
    assert all(np.array_equal(first[k], again[k]) for k in first)
    assert not np.array_equal(first["w0"], other["w0"])


@pytest.mark.bwrap
def test_it_trains_in_the_sandbox_and_drives_with_its_model(tmp_path, dataset):
    tmp_path.chmod(0o755)  # the sandbox user enters the submission, dataset and model
    settings = env_only(storage={"data_dir": tmp_path / "data"}, training={"train_timeout_s": 120})
    kind = usable(SandboxKind.bubblewrap, settings)
    submission = prepare_submission(
        EXAMPLE,
        tmp_path / "submission",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert submission.trains
    result = train(
        submission,
        dataset,
        tmp_path / "model",
        kind=kind,
        training=settings.training,
        **sandbox_args(settings),
    )
    assert result.ok, result.log
    assert "saved weights.npz" in result.log
    weights = np.load(tmp_path / "model" / "weights.npz")
    assert weights["w0"].shape[0] == weights["x_mean"].shape[0]

    summary = evaluate(
        EvaluationRequest(
            EXAMPLE,
            SHIPPED_PUBLIC_DIR,
            out_dir=tmp_path / "results",
            scenario_ids=[SCENARIO],
            sandbox=kind,
            model_dir=tmp_path / "model",
        ),
        **evaluate_args(get_settings()),
    )
    (entry,) = summary.scenarios
    assert entry.status == "done"
    (agent,) = entry.agents
    assert agent.steps > 10  # it drove with its model (no start-up failure)
    assert agent.reason not in {"agent_error", "init_timeout", "agent_exited"}


def test_evaluate_refuses_a_missing_model(tmp_path):
    from evaluator.runner.evaluate import ResultsDirError

    with pytest.raises(ResultsDirError, match="arena train"):
        evaluate(
            EvaluationRequest(
                EXAMPLE,
                SHIPPED_PUBLIC_DIR,
                out_dir=tmp_path / "results",
                scenario_ids=[SCENARIO],
                sandbox=SandboxKind.process,
                model_dir=tmp_path / "nowhere",
            ),
            **evaluate_args(get_settings()),
        )
