"""training_inspect: per-epoch history rows, run tags and edit version, per-frame scores of held-out predictions

Revision ID: 0008
Revises: 0007

The history of runs trained before this revision lives in their
checkpoints' ``metrics["history"]``; it is copied into ``training_epoch``
so their charts show it too. Their held-out predictions get per-frame
scores when an admin asks for them on the run's frames page.
"""

from alembic import op
import sqlalchemy as sa

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None

HISTORY_KEYS = ("lr", "train_loss", "loss", "max_f", "ap")


def upgrade():
    op.create_table(
        "training_epoch",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("fold", sa.String(length=120), nullable=False),
        sa.Column("epoch", sa.Integer(), nullable=False),
        *(sa.Column(key, sa.Float(), nullable=True) for key in HISTORY_KEYS),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["run_id"], ["training_run.id"], name=op.f("fk_training_epoch_run_id_training_run"),
                                ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_training_epoch")),
        sa.UniqueConstraint("run_id", "fold", "epoch", name=op.f("uq_training_epoch_run_id_fold_epoch")),
    )
    with op.batch_alter_table("training_epoch", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_training_epoch_run_id"), ["run_id"], unique=False)
    with op.batch_alter_table("training_run", schema=None) as batch_op:
        batch_op.add_column(sa.Column("tags", sa.JSON(), nullable=False, server_default="[]"))
        batch_op.add_column(sa.Column("version", sa.Integer(), nullable=False, server_default="1"))
    with op.batch_alter_table("training_prediction", schema=None) as batch_op:
        for column in ("f_score", "precision", "recall"):
            batch_op.add_column(sa.Column(column, sa.Float(), nullable=True))
    _copy_history()


def _copy_history():
    """Every finished fold's ``metrics["history"]`` as epoch rows."""
    checkpoints = sa.table(
        "training_checkpoint", sa.column("run_id", sa.Integer), sa.column("fold", sa.String),
        sa.column("metrics", sa.JSON), sa.column("created_at", sa.DateTime(timezone=True)),
    )
    epochs = sa.table(
        "training_epoch", sa.column("run_id", sa.Integer), sa.column("fold", sa.String), sa.column("epoch", sa.Integer),
        *(sa.column(key, sa.Float) for key in HISTORY_KEYS), sa.column("created_at", sa.DateTime(timezone=True)),
    )
    bind = op.get_bind()
    rows = []
    for run_id, fold, metrics, created_at in bind.execute(sa.select(checkpoints)):
        seen = set()
        for record in (metrics or {}).get("history", []):
            epoch = record.get("epoch")
            if not isinstance(epoch, int) or epoch in seen:
                continue
            seen.add(epoch)
            values = {key: record.get(key) if isinstance(record.get(key), int | float) else None for key in HISTORY_KEYS}
            rows.append({"run_id": run_id, "fold": fold, "epoch": epoch, "created_at": created_at, **values})
    if rows:
        op.bulk_insert(epochs, rows)


def downgrade():
    with op.batch_alter_table("training_prediction", schema=None) as batch_op:
        for column in ("recall", "precision", "f_score"):
            batch_op.drop_column(column)
    with op.batch_alter_table("training_run", schema=None) as batch_op:
        batch_op.drop_column("version")
        batch_op.drop_column("tags")
    with op.batch_alter_table("training_epoch", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_training_epoch_run_id"))
    op.drop_table("training_epoch")
