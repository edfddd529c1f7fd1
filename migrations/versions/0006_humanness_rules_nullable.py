"""humanness and rules are NULL when no agent drove a step

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-23 13:30:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006"
down_revision: str | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # batch mode: SQLite cannot ALTER a column's nullability in place.
    with op.batch_alter_table("scores") as batch:
        batch.alter_column("humanness", existing_type=sa.Float(), nullable=True)
        batch.alter_column("rules", existing_type=sa.Float(), nullable=True)


def downgrade() -> None:
    op.execute("UPDATE scores SET humanness = 0 WHERE humanness IS NULL")
    op.execute("UPDATE scores SET rules = 0 WHERE rules IS NULL")
    with op.batch_alter_table("scores") as batch:
        batch.alter_column("humanness", existing_type=sa.Float(), nullable=False)
        batch.alter_column("rules", existing_type=sa.Float(), nullable=False)
