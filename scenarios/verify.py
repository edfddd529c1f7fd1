"""The solvability check: run each scenario's expert and record why the unsolved ones are not.

Every episode runs in its own child process (libsumo: one simulation per process); ``jobs``
threads each wait on one child. Unsolved reasons go into the manifest's ``unsolvable_reason``
(``scenario.json`` is left alone so content hashes do not change).
"""

from __future__ import annotations

import functools
import hashlib
import json
import tempfile
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from arena.files import write_atomically
from arena.scenario import content_hash
from arena.suite import load_suite, write_manifest
from scenarios.experts import expert_factory, expert_interface, uses_log_replay
from sim.isolation import run_episode_isolated
from sim.result import EpisodeResult

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
    reason = unsolved_reason(result, expert)
    return VerifyResult(result.scenario_id, expert, reason is None, result.steps, reason)


def replay_unsolved(folder: Path, cache_dir: Path) -> str | None:
    """Why the log replay expert does not finish the non-reactive replay at ``folder`` (None
    when it does): what a suite build asks of every replay before it enters the suite. The
    verdict is a function of the folder's bytes and the simulator's code, and kept in
    ``cache_dir`` under both, so a rebuild drives no episode twice."""
    key = hashlib.sha256(f"{content_hash(folder)}\0{_simulator_code()}".encode()).hexdigest()
    cached = Path(cache_dir) / "verdicts" / f"{key[:32]}.json"
    if cached.is_file():
        return json.loads(cached.read_text())["reason"]
    with tempfile.TemporaryDirectory(prefix="arena-verify-") as tmp:
        reason = verify_scenario(folder, Path(tmp)).reason
    write_atomically(cached, json.dumps({"reason": reason}).encode())
    return reason


@functools.cache
def _simulator_code() -> str:
    """sha256 of the source the log replay expert's episode runs: the simulator, the contracts
    it reads scenarios and writes records by, and the expert."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    sources = [*(root / "sim").rglob("*.py"), *(root / "arena").glob("*.py")]
    for path in sorted([*sources, root / "scenarios" / "experts.py"]):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def unsolved_reason(result: EpisodeResult, expert: str, agents: Iterable[str] = ()) -> str | None:
    """Why ``expert`` did not solve the episode of ``result`` (``agents`` only, if named): a
    simulator error, or each mission it did not finish, how and when, with the failure's last
    line; None when solved."""
    if result.simulator_error:
        return f"simulator error: {_last_line(result.simulator_error)}"
    failed = [a for a in result.agents if not a.reached_goal and (not agents or a.id in agents)]
    if not failed:
        return None
    reason = f"{expert} expert: " + ", ".join(
        f"{a.id} {a.reason.value} at step {a.done_step}" for a in failed
    )
    return f"{reason} ({_last_line(result.detail)})" if result.detail.strip() else reason


def _last_line(text: str) -> str:
    return text.strip().splitlines()[-1][:200]


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
