"""the artifact store: uploads and records by key, optionally in the database

Submissions and scenario results name their files by artifact key (relative to the folder
store's root, the data folder) instead of by a path on one machine's disk.

Revision ID: 0005
Revises: 0004
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def _relative(path: str | None, anchor: str) -> str | None:
    """``/any/data/submissions/x/upload.zip`` -> ``submissions/x/upload.zip``."""
    if path is None:
        return None
    marker = f"/{anchor}/"
    return anchor + "/" + path.rsplit(marker, 1)[1] if marker in path else path


def upgrade() -> None:
    op.create_table(
        "artifacts",
        sa.Column("key", sa.String(length=512), nullable=False),
        sa.Column("sha256", sa.String(length=64), nullable=False),
        sa.Column("size", sa.BigInteger(), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("key", name=op.f("pk_artifacts")),
    )
    with op.batch_alter_table("submissions", schema=None) as batch_op:
        batch_op.alter_column("storage_dir", new_column_name="upload_key")
    with op.batch_alter_table("scenario_results", schema=None) as batch_op:
        batch_op.alter_column("record_path", new_column_name="record_key")
    connection = op.get_bind()
    submissions = sa.table("submissions", sa.column("id"), sa.column("upload_key"))
    for row_id, folder in connection.execute(sa.select(submissions.c.id, submissions.c.upload_key)):
        key = _relative(folder.rstrip("/") + "/upload.zip", "submissions")
        connection.execute(
            submissions.update().where(submissions.c.id == row_id).values(upload_key=key)
        )
    results = sa.table("scenario_results", sa.column("id"), sa.column("record_key"))
    for row_id, path in connection.execute(sa.select(results.c.id, results.c.record_key)):
        connection.execute(
            results.update()
            .where(results.c.id == row_id)
            .values(record_key=_relative(path, "runs"))
        )


def downgrade() -> None:
    with op.batch_alter_table("scenario_results", schema=None) as batch_op:
        batch_op.alter_column("record_key", new_column_name="record_path")
    with op.batch_alter_table("submissions", schema=None) as batch_op:
        batch_op.alter_column("upload_key", new_column_name="storage_dir")
    op.drop_table("artifacts")
