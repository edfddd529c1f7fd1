"""Whatever text an agent produces reaches the database through the worker's own code path
(``team_log_tail`` then ``record_scenario`` then the run's aggregation) without crashing it: a
fuzz of random bytes, lone surrogates, NULs, control characters and huge outputs.

A lone surrogate in an exception message used to crash the task in the log tail (a strict encode);
the claim was re-sent until it ended as an uncharged ``worker_lost``.
"""

from __future__ import annotations

import random

import pytest
from sqlalchemy import select

from arena.outcome import AgentOutcome, ScenarioStatus
from evaluator.runner import ScenarioOutcome
from server.core.artifacts import DatabaseStore
from server.models import ScenarioResult
from server.services import evaluation
from server.worker.episodes import team_log_tail
from server.worker.local import tail as tail_of
from tests.server.builders import agent, make_team, queued_submission, scenario_ids

FIXED = [
    "ValueError: \ud800",
    "\udcff\udcfe" * 1000,
    "nul \0 in the middle\0",
    "\x1b[2J\x1b[31mred\x07\x08\x7f",
    "\ud83d\ude00 paired surrogates, unpaired \ude00\ud83d",
    "x" * (3 << 20),  # 3 MiB
    "",
]


def agent_texts(count: int, seed: int = 22) -> list[str]:
    """``FIXED`` and random texts: bytes decoded as an agent's pipe would be (surrogateescape),
    random code points (surrogates included), and mixes of both."""
    rng = random.Random(seed)
    texts = list(FIXED)
    while len(texts) < count:
        size = rng.choice([1, 7, 300, 70_000])
        raw = rng.randbytes(size).decode("utf-8", "surrogateescape")
        points = "".join(chr(rng.randrange(0x110000)) for _ in range(min(size, 5000)))
        texts.append(rng.choice([raw, points, raw + points + raw]))
    return texts


@pytest.mark.parametrize("text", agent_texts(40), ids=lambda t: f"{len(t)}chars")
def test_tail_of_any_agent_text_is_storable_and_bounded(text, settings):
    tail = tail_of(text)
    assert (
        len(tail.encode("utf-8")) <= 3 * settings.sandbox.agent_log_tail_bytes
    )  # U+FFFD per bad byte
    assert "\0" not in tail
    tail.encode("utf-8")  # strict: no lone surrogate left


def test_agent_text_of_every_kind_is_recorded_and_the_run_aggregates(db, settings):
    team, _ = make_team(db, "fuzz")
    texts = agent_texts(24)
    while texts:
        submission_id = queued_submission(db, team)
        with db.session() as session:
            plan = evaluation.start_evaluation(session, settings, submission_id)
        for scenario_id in scenario_ids(plan):
            text = texts.pop() if texts else "fine"
            with db.session() as session:
                job = evaluation.claim_scenario(
                    session, settings.service, settings.sandbox, plan.run_id, scenario_id, "w"
                )
            outcome = ScenarioOutcome(
                scenario_id=scenario_id,
                status=ScenarioStatus.done,
                steps=0,
                agents=(AgentOutcome(**agent(False)),),
                record_path=None,
                log=text,
                error=text,
            )
            with db.session() as session:
                evaluation.record_scenario(
                    session, job, "w", outcome, team_log_tail(job, outcome), None
                )
        with db.session() as session:
            evaluation.finish_run(session, DatabaseStore(db), plan.run_id)
            rows = session.scalars(
                select(ScenarioResult).where(ScenarioResult.run_id == plan.run_id)
            ).all()
        assert len(rows) == len(scenario_ids(plan))
        for row in rows:
            assert "\0" not in row.log_tail
            row.log_tail.encode("utf-8")
