"""proposal_sources: an instance's proposal names its source (a trained run's model, depth, handled, saliency)

Revision ID: 0012
Revises: 0008

The mark of a pending proposal moves from ``proposed_by_run_id`` to
``proposal_source``: proposals pending from a trained run become "model".
"""

from alembic import op
import sqlalchemy as sa

revision = "0012"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade():
    with op.batch_alter_table("instance", schema=None) as batch_op:
        batch_op.add_column(sa.Column("proposal_source", sa.String(length=20), nullable=True))
    op.execute("UPDATE instance SET proposal_source = 'model' WHERE proposed_by_run_id IS NOT NULL")


def downgrade():
    # Proposals from a source other than a run were no proposals before this revision.
    with op.batch_alter_table("instance", schema=None) as batch_op:
        batch_op.drop_column("proposal_source")
