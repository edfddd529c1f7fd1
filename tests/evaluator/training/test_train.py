"""Training runs in real sandboxes: each named failure from a small hostile train.py, and a
good run whose output is packed and mounted read-only for its policy."""

from __future__ import annotations

import itertools
import textwrap
from pathlib import Path

import numpy as np
import pytest

from arena.config import SandboxKind, Settings
from arena.errors import DatasetError
from evaluator.training import TrainFailure, TrainingStopped, pack_model, train, unpack_model
from evaluator.training.checkpoint import CheckpointWatch, SnapshotFailed, restore
from submissions.intake import prepare_submission
from tests.evaluator.sandbox.agents import policy_source
from tests.evaluator.sandbox.conftest import ALL_KINDS, ISOLATING, usable
from tests.settings import sandbox_args, with_fields

# Reads the dataset, writes a model and a checkpoint folder: what a real train.py does.
GOOD = """
import os, pathlib
import numpy as np
data = np.load(pathlib.Path(os.environ["ARENA_DATASET_DIR"]) / "transitions.npz")
out = pathlib.Path(os.environ["ARENA_MODEL_DIR"])
print("rows", len(data["actions"]), flush=True)
(out / "ckpt").mkdir()
np.save(out / "ckpt" / "mean.npy", data["actions"].mean(axis=0))
(out / "weights.txt").write_text("ok")
print("seed", os.environ["ARENA_TRAIN_SEED"], flush=True)
"""


@pytest.fixture(scope="module")
def settings(tmp_path_factory: pytest.TempPathFactory) -> Settings:
    return with_fields(
        Settings(),
        storage={"data_dir": tmp_path_factory.mktemp("data")},
        training={"train_timeout_s": 20.0, "train_output_bytes": 2 * 1024**2},
        sandbox={"agent_memory_bytes": 512 * 1024**2},
    )


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("dataset")
    folder.chmod(0o755)
    rng = np.random.default_rng(0)
    np.savez(folder / "transitions.npz", actions=rng.normal(size=(50, 3)).astype(np.float32))
    (folder / "transitions.npz").chmod(0o644)
    return folder


def trainer(root: Path, settings: Settings, script: str):
    folder = root / "src"
    folder.mkdir(parents=True)
    (folder / "policy.py").write_text(policy_source())
    (folder / "train.py").write_text(textwrap.dedent(script))
    root.chmod(0o755)
    return prepare_submission(
        folder,
        root / "submission",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )


def run(tmp_path, settings, dataset, kind, script, **options):
    submission = trainer(tmp_path, settings, script)
    return train(
        submission,
        dataset,
        tmp_path / "out",
        kind=kind,
        training=settings.training,
        **sandbox_args(settings),
        **options,
    ), tmp_path / "out"


@pytest.fixture(params=ALL_KINDS)
def any_kind(request, settings) -> SandboxKind:
    return usable(request.param, settings)


@pytest.fixture(params=ISOLATING)
def kind(request, settings) -> SandboxKind:
    return usable(request.param, settings)


def test_a_good_run_reads_the_dataset_and_its_output_packs(tmp_path, settings, dataset, any_kind):
    result, out = run(tmp_path, settings, dataset, any_kind, GOOD)
    assert result.ok, result
    assert "rows 50" in result.log
    assert "seed 0" in result.log  # a phase of one seed
    assert (out / "weights.txt").read_text() == "ok"
    sha = pack_model(out, tmp_path / "model.tar.gz")
    assert sha == pack_model(out, tmp_path / "again.tar.gz")  # deterministic: names the model
    back = unpack_model(tmp_path / "model.tar.gz", tmp_path / "back")
    assert np.load(back / "ckpt" / "mean.npy").shape == (3,)


def test_the_seed_reaches_train_py(tmp_path, settings, dataset, any_kind):
    result, _ = run(tmp_path, settings, dataset, any_kind, GOOD, seed=7)
    assert result.ok, result
    assert "seed 7" in result.log


HOSTILE = {
    TrainFailure.train_error: ("raise RuntimeError('diverged at epoch 3')", "diverged at epoch 3"),
    TrainFailure.train_timeout: ("import time\nprint('epoch 1', flush=True)\ntime.sleep(60)", ""),
    TrainFailure.train_memory_limit: ("blocks = [bytearray(64 * 2**20) for _ in range(64)]", ""),
    TrainFailure.train_output_too_large: (
        "import os\nwith open(os.environ['ARENA_MODEL_DIR'] + '/big', 'wb') as f:\n"
        "    [f.write(b'x' * 2**20) for _ in range(8)]",
        "",
    ),
    TrainFailure.no_model_produced: ("print('trained, but saved nothing')", ""),
}


@pytest.mark.parametrize("failure", list(HOSTILE), ids=str)
def test_each_failure_has_its_name(tmp_path, settings, dataset, kind, failure):
    script, shown = HOSTILE[failure]
    # Only the timeout case needs a short budget; the others must fail by their own cause even
    # on a loaded machine (filling the memory limit takes seconds there).
    budget = 3.0 if failure is TrainFailure.train_timeout else 120.0
    result, _ = run(
        tmp_path, with_fields(settings, training={"train_timeout_s": budget}), dataset, kind, script
    )
    assert result.failure == failure, result
    assert shown in result.log
    if failure is TrainFailure.train_error:
        assert "Traceback" in result.log  # the team sees where it failed
    if failure is TrainFailure.train_timeout:
        assert "epoch 1" in result.log and result.elapsed_s < 15


def test_many_small_files_past_the_cap_are_stopped(tmp_path, settings, dataset, kind):
    script = """
    import os, time
    for i in range(40):
        with open(f"{os.environ['ARENA_MODEL_DIR']}/part{i}", "wb") as f:
            f.write(b"x" * 2**20)
        time.sleep(0.05)
    time.sleep(30)
    """
    result, _ = run(tmp_path, settings, dataset, kind, script)
    assert result.failure is TrainFailure.train_output_too_large
    assert result.elapsed_s < 15  # stopped while running, not at the budget


@pytest.mark.parametrize(
    ("script", "said"),
    [
        (  # 200,000 empty files passed the byte cap, and walking them starved the heartbeat
            """
            import os, time
            out = os.environ['ARENA_MODEL_DIR']
            for i in range(200_000):
                open(f"{out}/{i}", "wb").close()
            time.sleep(30)
            """,
            "more than",
        ),
        (
            """
            import os, time
            path = os.environ['ARENA_MODEL_DIR']
            for i in range(40):
                path += '/d'
                os.mkdir(path)
            time.sleep(30)
            """,
            "nested deeper",
        ),
    ],
    ids=["many empty files", "deep folders"],
)
def test_output_is_capped_in_entries_and_depth_without_delaying_progress(
    tmp_path, settings, dataset, kind, script, said
):
    beats: list[float] = []

    def progress(elapsed: float, log: str) -> bool:
        beats.append(elapsed)
        return True

    few = with_fields(settings, training={"train_output_files": 1000, "train_output_depth": 8})
    result, _ = run(
        tmp_path, few, dataset, kind, script, on_progress=progress, progress_every_s=0.5
    )
    assert result.failure is TrainFailure.train_output_too_large, result
    assert said in result.detail
    assert result.elapsed_s < 15  # stopped while running, not at the budget
    gaps = [later - earlier for earlier, later in itertools.pairwise(beats)]
    assert not gaps or max(gaps) < 2.0, gaps  # the progress report kept its rhythm


def test_the_caller_can_stop_a_run(tmp_path, settings, dataset, kind):
    seen = []

    def progress(elapsed: float, log: str) -> bool:
        seen.append(log)
        return "epoch 2" not in log

    script = (
        "import time\nfor i in range(100):\n    print('epoch', i, flush=True)\n    time.sleep(0.3)"
    )
    with pytest.raises(TrainingStopped):
        run(tmp_path, settings, dataset, kind, script, on_progress=progress, progress_every_s=0.5)
    assert "epoch 0" in seen[0]


def test_a_missing_dataset_is_named(tmp_path, settings):
    submission = trainer(tmp_path, settings, GOOD)
    with pytest.raises(DatasetError, match="arena dataset build"):
        train(
            submission,
            tmp_path / "nowhere",
            tmp_path / "out",
            training=settings.training,
            **sandbox_args(settings),
        )


def test_arena_train_keeps_train_py_output_on_success(tmp_path, dataset):
    """Printed and saved beside the model (never inside it: the model folder is evaluated)."""
    from arena_command import app
    from tests.cli_runner import CliRunner

    folder = tmp_path / "src"
    folder.mkdir()
    (folder / "policy.py").write_text(policy_source())
    (folder / "train.py").write_text(textwrap.dedent(GOOD))
    tmp_path.chmod(0o755)
    out = tmp_path / "model"
    result = CliRunner().invoke(
        app,
        [
            "train",
            str(folder),
            "--dataset",
            str(dataset),
            "--out",
            str(out),
            "--sandbox",
            "process",
            "--seed",
            "3",
        ],
    )
    assert result.exit_code == 0, result.output
    assert "rows 50" in result.output
    assert "seed 3" in result.output  # ARENA_TRAIN_SEED, as the service sets it
    assert "rows 50" in (tmp_path / "model.train.log").read_text()
    assert not (out / "model.train.log").exists()
    assert "model.train.log" in result.output.replace("\n", "")


# Resumes from what it finds in its output folder: rewrites one restored file, removes another.
RESUMING = """
import os, pathlib
out = pathlib.Path(os.environ["ARENA_MODEL_DIR"])
step_file = out / "ckpt" / "step.txt"
step = int(step_file.read_text()) if step_file.exists() else 0
print("resumed at", step, flush=True)
step_file.write_text(str(step + 1))
(out / "old.bin").unlink()
(out / "weights.txt").write_text(f"trained from step {step}")
"""


def test_a_resumed_training_finds_the_snapshot_and_may_rewrite_it(
    tmp_path, settings, dataset, any_kind
):
    earlier = tmp_path / "earlier"
    (earlier / "ckpt").mkdir(parents=True)
    (earlier / "ckpt" / "step.txt").write_text("41")
    (earlier / "old.bin").write_bytes(b"x")
    snapshot = tmp_path / "snapshot.tar.gz"
    assert CheckpointWatch(earlier, interval_s=1, max_bytes=1024, max_entries=10).snapshot(snapshot)
    result, out = run(tmp_path, settings, dataset, any_kind, RESUMING, resume_from=snapshot)
    assert result.ok, result
    assert "resumed at 41" in result.log
    assert (out / "ckpt" / "step.txt").read_text() == "42"
    assert not (out / "old.bin").exists()


def test_a_snapshot_is_taken_of_a_changed_folder_within_its_cap(tmp_path):
    folder = tmp_path / "out"
    folder.mkdir()
    archive = tmp_path / "snapshot.tar.gz"
    watch = CheckpointWatch(folder, interval_s=60, max_bytes=100, max_entries=10)
    assert not watch.due()  # not before its interval
    assert not watch.snapshot(archive)  # nothing to save yet
    (folder / "checkpoint.npz").write_bytes(b"epoch 1")
    assert watch.snapshot(archive)
    assert not watch.snapshot(tmp_path / "same.tar.gz") and not (tmp_path / "same.tar.gz").exists()
    (folder / "checkpoint.npz").write_bytes(b"epoch 2, longer")
    assert watch.snapshot(archive)
    assert (restore(archive, tmp_path / "back") / "checkpoint.npz").read_bytes() == (
        b"epoch 2, longer"
    )
    (folder / "checkpoint.npz").write_bytes(b"x" * 101)
    with pytest.raises(SnapshotFailed, match="past the checkpoint cap of 100"):
        watch.snapshot(tmp_path / "big.tar.gz")
    never = CheckpointWatch(folder, interval_s=0, max_bytes=100, max_entries=10)
    assert not never.due()  # an interval of 0: never
