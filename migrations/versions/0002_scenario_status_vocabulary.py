"""scenario results use the evaluation core's status vocabulary

The service stored its own scenario statuses ("success", "failure", "infrastructure_error");
local evaluation used ``arena.outcome.ScenarioStatus``. One vocabulary now: a charged scenario is
``done`` (its ``reason`` still says reached_goal or why not), our failures are
``simulator_error`` or ``evaluator_error``.

Revision ID: 0002
Revises: 0001
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_FORWARD = {"success": "done", "failure": "done", "infrastructure_error": "evaluator_error"}


def upgrade() -> None:
    results = sa.table("scenario_results", sa.column("status", sa.String))
    for old, new in _FORWARD.items():
        op.execute(results.update().where(results.c.status == old).values(status=new))


def downgrade() -> None:
    results = sa.table(
        "scenario_results", sa.column("status", sa.String), sa.column("reason", sa.String)
    )
    op.execute(
        results.update()
        .where(results.c.status == "done", results.c.reason == "reached_goal")
        .values(status="success")
    )
    op.execute(results.update().where(results.c.status == "done").values(status="failure"))
    op.execute(
        results.update()
        .where(results.c.status == "evaluator_error")
        .values(status="infrastructure_error")
    )
