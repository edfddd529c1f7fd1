"""Running a ported 2022 agent folder on public scenarios in each sandbox, as its tests do."""

from __future__ import annotations

from pathlib import Path

import pytest

from arena.config import SandboxKind, get_settings
from evaluator.runner import EvaluationRequest, evaluate
from evaluator.summary import Summary
from tests.settings import evaluate_args

AGENT_FAILURES = {"agent_error", "invalid_action", "agent_exited", "step_timeout", "init_timeout"}
SANDBOXES = [
    pytest.param(SandboxKind.docker, marks=pytest.mark.docker, id="docker"),
    pytest.param(SandboxKind.bubblewrap, marks=pytest.mark.bwrap, id="bubblewrap"),
    # Unisolated, but on the same interpreter and libraries where the machine has them.
    pytest.param(SandboxKind.process, id="process"),
]


def run_ported(
    agent: Path, scenarios: list[str], kind: SandboxKind, out: Path
) -> tuple[Summary, str]:
    """The summary of ``agent`` on the public ``scenarios`` in sandbox ``kind`` and its logs,
    checked to be complete with no agent failure (the logs' tail says why otherwise)."""
    from arena.suite import SHIPPED_PUBLIC_DIR

    summary = evaluate(
        EvaluationRequest(
            agent, SHIPPED_PUBLIC_DIR, out_dir=out, scenario_ids=scenarios, sandbox=kind
        ),
        **evaluate_args(get_settings()),
    )
    reasons = {(s.id, a.id): a.reason for s in summary.scenarios for a in s.agents}
    logs = "\n".join(p.read_text(errors="replace") for p in (out / "logs").glob("*.txt"))
    assert summary.complete and summary.uncharged == (), logs[-3000:]
    assert not {k: r for k, r in reasons.items() if r in AGENT_FAILURES}, (reasons, logs[-3000:])
    return summary, logs
