"""validation time: the worker time each upload's validation has used (charged to its team's
daily validation budget) and when its current claim took it

Revision ID: 0017
Revises: 0016
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0017"
down_revision: str | None = "0016"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("upload_validations", schema=None) as batch_op:
        batch_op.add_column(sa.Column("used_s", sa.Float(), server_default="0", nullable=False))
        batch_op.add_column(sa.Column("claimed_at", sa.DateTime(timezone=True), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("upload_validations", schema=None) as batch_op:
        batch_op.drop_column("claimed_at")
        batch_op.drop_column("used_s")
