"""uploads validated by a job: upload_validations (leased like trainings), at most one
`validating` submission per team, and the content key of a submission's requirements folder
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0014"
down_revision: str | None = "0013"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

ONE_VALIDATING = "uq_submissions_one_validating_per_team"
VALIDATING = sa.text("status = 'validating'")


def upgrade() -> None:
    op.create_table(
        "upload_validations",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("submission_id", sa.Integer(), nullable=False),
        sa.Column("worker", sa.String(length=255), nullable=False),
        sa.Column("claims", sa.Integer(), nullable=False),
        sa.Column("lease_expires_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("started_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("finished_at", sa.DateTime(timezone=True), nullable=True),
        sa.ForeignKeyConstraint(
            ["submission_id"],
            ["submissions.id"],
            name=op.f("fk_upload_validations_submission_id_submissions"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_upload_validations")),
        sa.UniqueConstraint("submission_id", name=op.f("uq_upload_validations_submission_id")),
    )
    with op.batch_alter_table("submissions", schema=None) as batch_op:
        batch_op.add_column(sa.Column("deps_key", sa.String(length=64), nullable=True))
    op.create_index(
        ONE_VALIDATING,
        "submissions",
        ["team_id"],
        unique=True,
        postgresql_where=VALIDATING,
        sqlite_where=VALIDATING,
    )


def downgrade() -> None:
    op.drop_table("upload_validations")
    op.drop_index(ONE_VALIDATING, table_name="submissions")
    with op.batch_alter_table("submissions", schema=None) as batch_op:
        batch_op.drop_column("deps_key")
