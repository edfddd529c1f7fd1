"""The solvability check: run each scenario's expert and record why the unsolved ones are not.

Every episode runs in its own child process (libsumo: one simulation per process); ``jobs``
threads each wait on one child. Unsolved reasons go into the manifest's ``unsolvable_reason``
(``scenario.json`` is left alone so content hashes do not change).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from arena.suite import load_suite, write_manifest
from scenarios.experts import expert_factory, expert_interface, uses_log_replay
from sim.isolation import run_episode_isolated

EPISODE_TIMEOUT_S = 600.0


@dataclass(frozen=True)
class VerifyResult:
    scenario_id: str
    expert: str  # "log replay" or "planner"
    solved: bool
    steps: int
    reason: str | None  # why not solved


def verify_scenario(folder: Path, record_dir: Path) -> VerifyResult:
    expert = "log replay" if uses_log_replay(folder) else "planner"
    result = run_episode_isolated(
        folder,
        expert_factory(folder),
        expert_interface(folder),
        record_path=record_dir / f"{folder.name}.npz",
        timeout_s=EPISODE_TIMEOUT_S,
    )
    failed = [a for a in result.agents if not a.reached_goal]
    reason = None
    if result.simulator_error:
        reason = f"simulator error: {result.simulator_error.strip().splitlines()[-1][:200]}"
    elif failed:
        reason = f"{expert} expert: " + ", ".join(
            f"{a.id} {a.reason.value} at step {a.done_step}" for a in failed
        )
    return VerifyResult(result.scenario_id, expert, reason is None, result.steps, reason)


def verify_suite(
    suite_dir: Path,
    ids: list[str],
    jobs: int = 1,
    on_result: Callable[[VerifyResult], None] = lambda _: None,
) -> list[VerifyResult]:
    """Verify ``ids`` of the built suite at ``suite_dir``; updates its manifest."""
    suite_dir = Path(suite_dir)
    with tempfile.TemporaryDirectory(prefix="arena-verify-") as tmp:
        results: dict[str, VerifyResult] = {}

        def run(sid: str) -> VerifyResult:
            r = verify_scenario(suite_dir / sid, Path(tmp))
            on_result(r)
            return r

        with ThreadPoolExecutor(max_workers=jobs) as pool:
            for r in pool.map(run, ids):
                results[r.scenario_id] = r
    manifest = load_suite(suite_dir).manifest
    entries = tuple(
        entry.model_copy(update={"unsolvable_reason": results[entry.id].reason})
        if entry.id in results
        else entry
        for entry in manifest.scenarios
    )
    write_manifest(suite_dir, manifest.model_copy(update={"scenarios": entries}))
    return [results[sid] for sid in ids]
