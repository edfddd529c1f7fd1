"""claim number: the fence token of every job's row has one name, ``claim_number`` (it was
``attempts`` on scenario_results, ``claims`` on training_jobs and upload_validations)

Revision ID: 0019
Revises: 0018
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0019"
down_revision: str | None = "0018"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# Each job table and the name its fence token had before.
OLD_NAMES = {
    "scenario_results": "attempts",
    "training_jobs": "claims",
    "upload_validations": "claims",
}


def _rename(table: str, old: str, new: str) -> None:
    with op.batch_alter_table(table, schema=None) as batch_op:
        batch_op.alter_column(
            old, new_column_name=new, existing_type=sa.Integer(), existing_nullable=False
        )


def upgrade() -> None:
    for table, old in OLD_NAMES.items():
        _rename(table, old, "claim_number")


def downgrade() -> None:
    for table, old in OLD_NAMES.items():
        _rename(table, "claim_number", old)
