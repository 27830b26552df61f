"""proposals: instances proposed by a training run ("Suggest"), and the run that proposed into an annotation

Revision ID: 0006
Revises: 0005
"""

from alembic import op
import sqlalchemy as sa

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

# Each table gets the same two columns: the proposing run and its fold's checkpoint.
COLUMNS = (("proposed_by_run_id", "training_run"), ("proposed_by_checkpoint_id", "training_checkpoint"))


def upgrade():
    for table in ("annotation", "instance"):
        with op.batch_alter_table(table, schema=None) as batch_op:
            for column, target in COLUMNS:
                batch_op.add_column(sa.Column(column, sa.Integer(), nullable=True))
                batch_op.create_foreign_key(
                    batch_op.f(f"fk_{table}_{column}_{target}"), target, [column], ["id"], ondelete="SET NULL"
                )


def downgrade():
    for table in ("instance", "annotation"):
        with op.batch_alter_table(table, schema=None) as batch_op:
            for column, target in reversed(COLUMNS):
                batch_op.drop_constraint(batch_op.f(f"fk_{table}_{column}_{target}"), type_="foreignkey")
                batch_op.drop_column(column)
