"""labelling: review fields, stable instance keys, saved GrabCut sessions

Revision ID: 0002
Revises: 0001
"""

from alembic import op
import sqlalchemy as sa

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade():
    with op.batch_alter_table("annotation", schema=None) as batch_op:
        batch_op.add_column(sa.Column("reviewer_id", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("reviewed_at", sa.DateTime(timezone=True), nullable=True))
        batch_op.create_foreign_key(batch_op.f("fk_annotation_reviewer_id_user"), "user", ["reviewer_id"], ["id"])

    with op.batch_alter_table("instance", schema=None) as batch_op:
        batch_op.add_column(sa.Column("key", sa.String(length=40), nullable=True))

    op.create_table(
        "grabcut_state",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("user_id", sa.Integer(), nullable=False),
        sa.Column("frame_id", sa.Integer(), nullable=False),
        sa.Column("instance_key", sa.String(length=40), nullable=False),
        sa.Column("state", sa.LargeBinary(), nullable=False),
        sa.Column("revision", sa.String(length=32), nullable=False),
        sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["frame_id"], ["frame.id"], name=op.f("fk_grabcut_state_frame_id_frame"), ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(["user_id"], ["user.id"], name=op.f("fk_grabcut_state_user_id_user"), ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_grabcut_state")),
        sa.UniqueConstraint(
            "user_id", "frame_id", "instance_key", name=op.f("uq_grabcut_state_user_id_frame_id_instance_key")
        ),
    )
    with op.batch_alter_table("grabcut_state", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_grabcut_state_frame_id"), ["frame_id"], unique=False)


def downgrade():
    with op.batch_alter_table("grabcut_state", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_grabcut_state_frame_id"))
    op.drop_table("grabcut_state")

    with op.batch_alter_table("instance", schema=None) as batch_op:
        batch_op.drop_column("key")

    with op.batch_alter_table("annotation", schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f("fk_annotation_reviewer_id_user"), type_="foreignkey")
        batch_op.drop_column("reviewed_at")
        batch_op.drop_column("reviewer_id")
