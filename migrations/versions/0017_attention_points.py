"""attention points: the points and Gaussian width an annotation's mask was made from (flask egonet import-points)

Revision ID: 0017
Revises: 0016
"""

from alembic import op
import sqlalchemy as sa

revision = "0017"
down_revision = "0016"
branch_labels = None
depends_on = None


def upgrade():
    op.create_table(
        "attention_points",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("annotation_id", sa.Integer(), nullable=False),
        sa.Column("points", sa.JSON(), nullable=False),
        sa.Column("sigma_px", sa.Float(), nullable=False),
        sa.Column("sigma_scaled", sa.Boolean(), nullable=False),
        sa.Column("source", sa.String(length=200), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["annotation_id"], ["annotation.id"], name=op.f("fk_attention_points_annotation_id_annotation"),
                                ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_attention_points")),
        sa.UniqueConstraint("annotation_id", name=op.f("uq_attention_points_annotation_id")),
    )


def downgrade():
    op.drop_table("attention_points")
