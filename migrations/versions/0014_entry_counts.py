"""entry counts: study entry throttled per (scope, address, window) with one row each, and growing waits

Revision ID: 0014
Revises: 0013
"""

from alembic import op
import sqlalchemy as sa

revision = "0014"
down_revision = "0013"
branch_labels = None
depends_on = None


def upgrade():
    # The counts are only of the current window: nothing worth carrying over.
    with op.batch_alter_table("study_entry_failures", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_study_entry_failures_study_id"))
        batch_op.drop_index(batch_op.f("ix_study_entry_failures_address"))
    op.drop_table("study_entry_failures")
    op.create_table(
        "study_entry_counts",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("scope", sa.String(length=32), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=True),
        sa.Column("address", sa.String(length=64), nullable=False),
        sa.Column("window", sa.BigInteger(), nullable=False),
        sa.Column("count", sa.Integer(), nullable=False),
        sa.Column("since", sa.DateTime(timezone=True), nullable=False),
        sa.Column("wait_until", sa.DateTime(timezone=True), nullable=True),
        sa.ForeignKeyConstraint(["study_id"], ["study.id"], name=op.f("fk_study_entry_counts_study_id_study"), ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_study_entry_counts")),
        sa.UniqueConstraint("scope", "address", "window", name=op.f("uq_study_entry_counts_scope_address_window")),
    )
    with op.batch_alter_table("study_entry_counts", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_study_entry_counts_study_id"), ["study_id"], unique=False)


def downgrade():
    with op.batch_alter_table("study_entry_counts", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_study_entry_counts_study_id"))
    op.drop_table("study_entry_counts")
    op.create_table(
        "study_entry_failures",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=True),
        sa.Column("address", sa.String(length=64), nullable=False),
        sa.Column("failures", sa.Integer(), nullable=False),
        sa.Column("since", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["study_id"], ["study.id"], name=op.f("fk_study_entry_failures_study_id_study"),
                                ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_study_entry_failures")),
    )
    with op.batch_alter_table("study_entry_failures", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_study_entry_failures_address"), ["address"], unique=False)
        batch_op.create_index(batch_op.f("ix_study_entry_failures_study_id"), ["study_id"], unique=False)
