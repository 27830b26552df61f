"""pilots and withdrawal: pilot participants, withdrawn participants, failed study entries per study and address

Revision ID: 0013
Revises: 0012
"""

from alembic import op
import sqlalchemy as sa

revision = "0013"
down_revision = "0012"
branch_labels = None
depends_on = None


def upgrade():
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
    with op.batch_alter_table("study_participant", schema=None) as batch_op:
        batch_op.add_column(sa.Column("pilot", sa.Boolean(), server_default=sa.false(), nullable=False))
        batch_op.add_column(sa.Column("withdrawn_at", sa.DateTime(timezone=True), nullable=True))
        batch_op.add_column(sa.Column("withdrawn_by_id", sa.Integer(), nullable=True))
        batch_op.create_foreign_key(batch_op.f("fk_study_participant_withdrawn_by_id_user"), "user", ["withdrawn_by_id"], ["id"])


def downgrade():
    with op.batch_alter_table("study_participant", schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f("fk_study_participant_withdrawn_by_id_user"), type_="foreignkey")
        batch_op.drop_column("withdrawn_by_id")
        batch_op.drop_column("withdrawn_at")
        batch_op.drop_column("pilot")
    with op.batch_alter_table("study_entry_failures", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_study_entry_failures_study_id"))
        batch_op.drop_index(batch_op.f("ix_study_entry_failures_address"))
    op.drop_table("study_entry_failures")
