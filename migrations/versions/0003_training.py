"""training: runs, checkpoints, predictions

Revision ID: 0003
Revises: 0002
"""

from alembic import op
import sqlalchemy as sa

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def _time(name: str, *, nullable: bool) -> sa.Column:
    return sa.Column(name, sa.DateTime(timezone=True), nullable=nullable)


def _enum(name: str, *values: str) -> sa.Enum:
    return sa.Enum(*values, name=name, native_enum=False, length=20)


def upgrade():
    op.create_table(
        "training_run",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("model_name", sa.String(length=40), nullable=False),
        sa.Column("model_options", sa.JSON(), nullable=False),
        sa.Column("folds", _enum("foldsmode", "loao", "single"), nullable=False),
        sa.Column("epochs", sa.Integer(), nullable=False),
        sa.Column("device", sa.String(length=10), nullable=False),
        sa.Column("seed", sa.Integer(), nullable=False),
        sa.Column("config", sa.JSON(), nullable=False),
        sa.Column("status", _enum("runstatus", "queued", "running", "done", "failed", "cancelled"), nullable=False),
        sa.Column("progress", sa.Float(), nullable=False),
        sa.Column("loss", sa.Float(), nullable=True),
        sa.Column("eta_s", sa.Float(), nullable=True),
        sa.Column("message", sa.Text(), nullable=True),
        sa.Column("metrics", sa.JSON(), nullable=False),
        sa.Column("created_by_id", sa.Integer(), nullable=True),
        _time("created_at", nullable=False),
        _time("started_at", nullable=True),
        _time("finished_at", nullable=True),
        _time("updated_at", nullable=False),
        sa.ForeignKeyConstraint(["created_by_id"], ["user.id"], name=op.f("fk_training_run_created_by_id_user")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_training_run")),
    )
    with op.batch_alter_table("training_run", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_training_run_status"), ["status"], unique=False)

    op.create_table(
        "training_checkpoint",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("fold", sa.String(length=120), nullable=False),
        sa.Column("path", sa.String(length=500), nullable=False),
        sa.Column("epochs", sa.Integer(), nullable=False),
        sa.Column("metrics", sa.JSON(), nullable=False),
        sa.Column("test_frame_ids", sa.JSON(), nullable=False),
        _time("created_at", nullable=False),
        sa.ForeignKeyConstraint(
            ["run_id"], ["training_run.id"], name=op.f("fk_training_checkpoint_run_id_training_run"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_training_checkpoint")),
        sa.UniqueConstraint("run_id", "fold", name=op.f("uq_training_checkpoint_run_id_fold")),
    )
    with op.batch_alter_table("training_checkpoint", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_training_checkpoint_run_id"), ["run_id"], unique=False)

    op.create_table(
        "training_prediction",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("checkpoint_id", sa.Integer(), nullable=False),
        sa.Column("frame_id", sa.Integer(), nullable=False),
        sa.Column("path", sa.String(length=200), nullable=False),
        sa.Column("held_out", sa.Boolean(), nullable=False),
        _time("created_at", nullable=False),
        sa.ForeignKeyConstraint(
            ["checkpoint_id"],
            ["training_checkpoint.id"],
            name=op.f("fk_training_prediction_checkpoint_id_training_checkpoint"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["frame_id"], ["frame.id"], name=op.f("fk_training_prediction_frame_id_frame"), ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(
            ["run_id"], ["training_run.id"], name=op.f("fk_training_prediction_run_id_training_run"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_training_prediction")),
        sa.UniqueConstraint(
            "checkpoint_id", "frame_id", name=op.f("uq_training_prediction_checkpoint_id_frame_id")
        ),
    )
    with op.batch_alter_table("training_prediction", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_training_prediction_checkpoint_id"), ["checkpoint_id"], unique=False)
        batch_op.create_index(batch_op.f("ix_training_prediction_frame_id"), ["frame_id"], unique=False)
        batch_op.create_index(batch_op.f("ix_training_prediction_run_id"), ["run_id"], unique=False)


def downgrade():
    with op.batch_alter_table("training_prediction", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_training_prediction_run_id"))
        batch_op.drop_index(batch_op.f("ix_training_prediction_frame_id"))
        batch_op.drop_index(batch_op.f("ix_training_prediction_checkpoint_id"))
    op.drop_table("training_prediction")
    with op.batch_alter_table("training_checkpoint", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_training_checkpoint_run_id"))
    op.drop_table("training_checkpoint")
    with op.batch_alter_table("training_run", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_training_run_status"))
    op.drop_table("training_run")
