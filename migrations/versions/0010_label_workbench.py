"""label workbench: a reviewer's fix on an annotation, undo histories kept on the server, who has a frame open

Revision ID: 0010
Revises: 0006
"""

from alembic import op
import sqlalchemy as sa

revision = "0010"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade():
    with op.batch_alter_table("annotation", schema=None) as batch_op:
        batch_op.add_column(sa.Column("fixed_by_id", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("fixed_at", sa.DateTime(timezone=True), nullable=True))
        batch_op.create_foreign_key(batch_op.f("fk_annotation_fixed_by_id_user"), "user", ["fixed_by_id"], ["id"])

    op.create_table(
        "edit_history",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("user_id", sa.Integer(), nullable=False),
        sa.Column("annotation_id", sa.Integer(), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["annotation_id"], ["annotation.id"],
                                name=op.f("fk_edit_history_annotation_id_annotation"), ondelete="CASCADE"),
        sa.ForeignKeyConstraint(["user_id"], ["user.id"], name=op.f("fk_edit_history_user_id_user"), ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_edit_history")),
        sa.UniqueConstraint("user_id", "annotation_id", name=op.f("uq_edit_history_user_id_annotation_id")),
    )
    with op.batch_alter_table("edit_history", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_edit_history_annotation_id"), ["annotation_id"], unique=False)

    op.create_table(
        "frame_presence",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("frame_id", sa.Integer(), nullable=False),
        sa.Column("user_id", sa.Integer(), nullable=False),
        sa.Column("opened_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("seen_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["frame_id"], ["frame.id"], name=op.f("fk_frame_presence_frame_id_frame"),
                                ondelete="CASCADE"),
        sa.ForeignKeyConstraint(["user_id"], ["user.id"], name=op.f("fk_frame_presence_user_id_user"), ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_frame_presence")),
        sa.UniqueConstraint("frame_id", "user_id", name=op.f("uq_frame_presence_frame_id_user_id")),
    )
    with op.batch_alter_table("frame_presence", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_frame_presence_frame_id"), ["frame_id"], unique=False)
        batch_op.create_index(batch_op.f("ix_frame_presence_seen_at"), ["seen_at"], unique=False)


def downgrade():
    with op.batch_alter_table("frame_presence", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_frame_presence_seen_at"))
        batch_op.drop_index(batch_op.f("ix_frame_presence_frame_id"))
    op.drop_table("frame_presence")
    with op.batch_alter_table("edit_history", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_edit_history_annotation_id"))
    op.drop_table("edit_history")
    with op.batch_alter_table("annotation", schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f("fk_annotation_fixed_by_id_user"), type_="foreignkey")
        batch_op.drop_column("fixed_at")
        batch_op.drop_column("fixed_by_id")
