"""`arena up` stopping removes the sandboxes its own worker left, and no other: another service's
(another data folder) or a local `arena evaluate` on the same host keeps running."""

from __future__ import annotations

import uuid

import pytest
from rich.console import Console

from evaluator.sandbox import start
from evaluator.sandbox.backend import owner_labels
from server.embedded import _remove_leftover_sandboxes
from tests.evaluator.sandbox.agents import agent, observation
from tests.evaluator.sandbox.conftest import ISOLATING, leftovers, usable
from tests.server.service_stack import shared_dir
from tests.settings import env_only, sandbox_args


@pytest.mark.parametrize("kind", ISOLATING)
def test_stopping_removes_only_this_data_folders_sandboxes(kind, tmp_path) -> None:
    ours, theirs = (
        env_only(
            storage={"data_dir": shared_dir(f"arena-owner-{name}-")}, sandbox={"init_timeout_s": 20}
        )
        for name in ("ours", "theirs")
    )
    kind = usable(kind, ours)
    labels = {"driving-arena.test": uuid.uuid4().hex}
    mine = start(
        agent(tmp_path / "a", ours),
        kind=kind,
        labels=labels,
        **sandbox_args(ours),
    )
    other = start(
        agent(tmp_path / "b", theirs),
        kind=kind,
        labels=labels,
        **sandbox_args(theirs),
    )
    of_ours, of_theirs = (
        {**labels, **owner_labels(s.storage.resolved_data_dir)} for s in (ours, theirs)
    )
    try:
        assert leftovers(kind, of_ours) and leftovers(kind, of_theirs)
        _remove_leftover_sandboxes(Console(), **sandbox_args(ours))
        assert leftovers(kind, of_ours) == []
        assert other.act(observation()) == {"Agent_0": [1.0, 0.0]}
    finally:
        mine.close()
        other.close()
    assert leftovers(kind, labels) == []
