"""the agent's CPU budget: the CPU time each episode's agent used, and the three CPU limits (an
act's, an episode's, an evaluation's) as a phase's override and as the limits a run was
evaluated under

Revision ID: 0015
Revises: 0014
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0015"
down_revision: str | None = "0014"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

LIMITS = ("step_cpu_s", "episode_cpu_s", "evaluation_cpu_s")


def upgrade() -> None:
    with op.batch_alter_table("scenario_results", schema=None) as batch_op:
        batch_op.add_column(sa.Column("agent_cpu_s", sa.Float(), nullable=True))
    for table in ("phases", "evaluation_runs"):
        with op.batch_alter_table(table, schema=None) as batch_op:
            for column in LIMITS:
                batch_op.add_column(sa.Column(column, sa.Float(), nullable=True))


def downgrade() -> None:
    for table in ("phases", "evaluation_runs"):
        with op.batch_alter_table(table, schema=None) as batch_op:
            for column in LIMITS:
                batch_op.drop_column(column)
    with op.batch_alter_table("scenario_results", schema=None) as batch_op:
        batch_op.drop_column("agent_cpu_s")
