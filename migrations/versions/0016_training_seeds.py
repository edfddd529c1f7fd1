"""training seeds: a phase trains each offline submission with N seeds (phases.training_seeds);
each training job knows its seed set, its seed and the set's size; a set of several seeds is
scored in seed_set_scores

Revision ID: 0016
Revises: 0015
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0016"
down_revision: str | None = "0015"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("phases", schema=None) as batch_op:
        batch_op.add_column(
            sa.Column("training_seeds", sa.Integer(), server_default="1", nullable=False)
        )
    with op.batch_alter_table("training_jobs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("seed_set", sa.Integer(), server_default="1", nullable=False))
        batch_op.add_column(sa.Column("seed", sa.Integer(), server_default="0", nullable=False))
        batch_op.add_column(sa.Column("seeds", sa.Integer(), server_default="1", nullable=False))
    # Every earlier attempt trained one seed: its own set.
    op.execute("UPDATE training_jobs SET seed_set = attempt")
    op.create_table(
        "seed_set_scores",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("submission_id", sa.Integer(), nullable=False),
        sa.Column("seed_set", sa.Integer(), nullable=False),
        sa.Column("attempt", sa.Integer(), nullable=False),
        sa.Column("episodes_per_scenario", sa.Integer(), nullable=False),
        sa.Column("completion", sa.Float(), nullable=False),
        sa.Column("time", sa.Float(), nullable=False),
        sa.Column("humanness", sa.Float(), nullable=True),
        sa.Column("rules", sa.Float(), nullable=True),
        sa.Column("completion_low", sa.Float(), nullable=True),
        sa.Column("completion_high", sa.Float(), nullable=True),
        sa.Column("seed_completion_min", sa.Float(), nullable=False),
        sa.Column("seed_completion_max", sa.Float(), nullable=False),
        sa.Column("seed_completion_std", sa.Float(), nullable=False),
        sa.Column("per_seed", sa.JSON(), nullable=False),
        sa.Column("families", sa.JSON(), nullable=False),
        sa.Column("samples", sa.JSON(), nullable=True),
        sa.Column("profile", sa.String(length=64), nullable=False),
        sa.Column("profile_version", sa.String(length=32), nullable=False),
        sa.Column("computed_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["submission_id"],
            ["submissions.id"],
            name=op.f("fk_seed_set_scores_submission_id_submissions"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_seed_set_scores")),
        sa.UniqueConstraint(
            "submission_id", "seed_set", name=op.f("uq_seed_set_scores_submission_id")
        ),
    )
    op.create_index(op.f("ix_seed_set_scores_submission_id"), "seed_set_scores", ["submission_id"])


def downgrade() -> None:
    op.drop_index(op.f("ix_seed_set_scores_submission_id"), table_name="seed_set_scores")
    op.drop_table("seed_set_scores")
    with op.batch_alter_table("training_jobs", schema=None) as batch_op:
        batch_op.drop_column("seeds")
        batch_op.drop_column("seed")
        batch_op.drop_column("seed_set")
    with op.batch_alter_table("phases", schema=None) as batch_op:
        batch_op.drop_column("training_seeds")
