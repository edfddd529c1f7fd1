"""adaptive evaluation: a phase's target half-width of completion's interval and its cap on
episodes per reactive scenario, copied into each run with the size of its rounds

Revision ID: 0012
Revises: 0011
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0012"
down_revision: str | None = "0011"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("phases", schema=None) as batch_op:
        batch_op.add_column(sa.Column("adaptive_target", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("max_episodes", sa.Integer(), nullable=True))
    with op.batch_alter_table("evaluation_runs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("adaptive_target", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("max_episodes", sa.Integer(), nullable=True))
        batch_op.add_column(
            sa.Column("episode_round", sa.Integer(), server_default="1", nullable=False)
        )


def downgrade() -> None:
    with op.batch_alter_table("evaluation_runs", schema=None) as batch_op:
        batch_op.drop_column("episode_round")
        batch_op.drop_column("max_episodes")
        batch_op.drop_column("adaptive_target")
    with op.batch_alter_table("phases", schema=None) as batch_op:
        batch_op.drop_column("max_episodes")
        batch_op.drop_column("adaptive_target")
