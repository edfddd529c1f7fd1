"""competition phases: a public validation phase and the hidden final, open-ended

Every submission belongs to a phase; those made before phases existed were evaluated on the
hidden suite, so they belong to `final`.

Revision ID: 0003
Revises: 0002
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    phases = op.create_table(
        "phases",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=32), nullable=False),
        sa.Column("suite", sa.String(length=512), nullable=False),
        sa.Column(
            "visibility",
            sa.Enum("full", "hidden", name="visibility", native_enum=False, length=16),
            nullable=False,
        ),
        sa.Column("starts_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("ends_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("daily_quota", sa.Integer(), nullable=True),
        sa.Column("scoring_profile", sa.String(length=64), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_phases")),
        sa.UniqueConstraint("name", name=op.f("uq_phases_name")),
    )
    op.bulk_insert(
        phases,
        [
            {"name": "validation", "suite": "public", "visibility": "full"},
            {"name": "final", "suite": "hidden", "visibility": "hidden"},
        ],
    )
    with op.batch_alter_table("submissions", schema=None) as batch_op:
        batch_op.add_column(
            sa.Column("phase", sa.String(length=32), server_default="final", nullable=False)
        )
        batch_op.create_index(batch_op.f("ix_submissions_phase"), ["phase"], unique=False)
        batch_op.create_foreign_key(
            batch_op.f("fk_submissions_phase_phases"), "phases", ["phase"], ["name"]
        )


def downgrade() -> None:
    with op.batch_alter_table("submissions", schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f("fk_submissions_phase_phases"), type_="foreignkey")
        batch_op.drop_index(batch_op.f("ix_submissions_phase"))
        batch_op.drop_column("phase")
    op.drop_table("phases")
