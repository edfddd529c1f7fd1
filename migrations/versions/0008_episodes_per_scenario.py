"""several episodes per reactive scenario: the phase's count, the run's, an episode index per
result, and the completion interval of a score

Revision ID: 0008
Revises: 0007
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0008"
down_revision: str | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("phases", schema=None) as batch_op:
        batch_op.add_column(sa.Column("episodes_per_scenario", sa.Integer(), nullable=True))
    with op.batch_alter_table("evaluation_runs", schema=None) as batch_op:
        # Every run so far ran one episode per scenario: its scenario count is its episode count.
        batch_op.alter_column("scenario_count", new_column_name="episode_count")
        batch_op.add_column(
            sa.Column("episodes_per_scenario", sa.Integer(), server_default="1", nullable=False)
        )
    with op.batch_alter_table("scenario_results", schema=None) as batch_op:
        batch_op.add_column(sa.Column("episode", sa.Integer(), server_default="0", nullable=False))
        batch_op.drop_constraint("uq_scenario_results_run_id", type_="unique")
        batch_op.create_unique_constraint(
            "uq_scenario_results_run_id", ["run_id", "scenario_id", "episode"]
        )
    with op.batch_alter_table("scores", schema=None) as batch_op:
        batch_op.add_column(sa.Column("completion_low", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("completion_high", sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("scores", schema=None) as batch_op:
        batch_op.drop_column("completion_high")
        batch_op.drop_column("completion_low")
    # Later episodes have no place in the old key: only each scenario's first one is kept.
    op.execute("DELETE FROM scenario_results WHERE episode <> 0")
    with op.batch_alter_table("scenario_results", schema=None) as batch_op:
        batch_op.drop_constraint("uq_scenario_results_run_id", type_="unique")
        batch_op.create_unique_constraint("uq_scenario_results_run_id", ["run_id", "scenario_id"])
        batch_op.drop_column("episode")
    with op.batch_alter_table("evaluation_runs", schema=None) as batch_op:
        batch_op.drop_column("episodes_per_scenario")
        batch_op.alter_column("episode_count", new_column_name="scenario_count")
    with op.batch_alter_table("phases", schema=None) as batch_op:
        batch_op.drop_column("episodes_per_scenario")
