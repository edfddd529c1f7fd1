"""Builders of agents (good and hostile) as prepared submissions."""

from __future__ import annotations

import textwrap
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from arena.config import SandboxKind, Settings
from evaluator.sandbox import AgentHandle, start
from evaluator.sandbox.warm import WarmAgent
from submissions.intake import PreparedSubmission, prepare_submission
from submissions.sample import sample_observation as observation
from tests.settings import sandbox_args

__all__ = ["agent", "handle_of", "observation", "policy_source"]


def policy_source(act: str = "return {k: [1.0, 0.0] for k in obs}", init: str = "pass") -> str:
    """A policy.py whose ``__init__`` and ``act`` bodies are the given code."""
    return (
        "import math, os, socket, sys, time\n"
        "import numpy as np\n\n"
        "class Policy:\n"
        "    def __init__(self):\n"
        f"{textwrap.indent(textwrap.dedent(init), ' ' * 8)}\n"
        "    def act(self, obs):\n"
        f"{textwrap.indent(textwrap.dedent(act), ' ' * 8)}\n"
    )


def agent(
    root: Path,
    settings: Settings,
    *,
    act: str | None = None,
    init: str = "pass",
    source=None,
    agent_yaml: str | None = None,
) -> PreparedSubmission:
    folder = root / "src"
    folder.mkdir(parents=True)
    text = source or (policy_source(act, init) if act else policy_source(init=init))
    (folder / "policy.py").write_text(text)
    if agent_yaml is not None:
        (folder / "agent.yaml").write_text(agent_yaml)
    return prepare_submission(
        folder,
        root / "submission",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )


@contextmanager
def handle_of(
    submission: PreparedSubmission,
    kind: SandboxKind,
    settings: Settings,
    labels: dict[str, str],
    warm: bool,
) -> Iterator[AgentHandle]:
    """The started agent of ``submission``: in a sandbox of its own (cold), or forked by a warm
    zygote (``warm``), as an evaluation starts it."""
    if not warm:
        with start(submission, kind=kind, labels=labels, **sandbox_args(settings)) as handle:
            yield handle
        return
    zygote = WarmAgent.start(
        submission, kind, settings.sandbox, settings.storage.resolved_data_dir, labels=labels
    )
    try:
        forked = zygote.fork(settings.sandbox, {})
        try:
            with forked.start() as handle:
                yield handle
        finally:
            forked.close()
    finally:
        zygote.close()
