"""proposals claim nothing: an open annotation holding only proposals nobody accepted is "todo", not in progress

Suggest used to leave such annotations in progress, which took their frames
out of everyone else's "next unlabelled" and the Label page's counts while
the Activities page still counted them as left to label. The code now keeps
them "todo" (``app.services.labelling.annotations._next_status``); this
brings the ones already there in line. Downgrade puts every "todo"
annotation back in progress, as the code before wrote them.

Revision ID: 0018
Revises: 0017
"""

from alembic import op
import sqlalchemy as sa

revision = "0018"
down_revision = "0017"
branch_labels = None
depends_on = None


def upgrade():
    annotation = sa.table("annotation", sa.column("id"), sa.column("status"), sa.column("no_action_object"))
    instance = sa.table("instance", sa.column("annotation_id"), sa.column("proposal_source"))
    own = sa.exists().where(instance.c.annotation_id == annotation.c.id, instance.c.proposal_source.is_(None))
    op.execute(
        annotation.update()
        .where(annotation.c.status == "in_progress", annotation.c.no_action_object.is_(sa.false()), ~own)
        .values(status="todo")
    )


def downgrade():
    annotation = sa.table("annotation", sa.column("status"))
    op.execute(annotation.update().where(annotation.c.status == "todo").values(status="in_progress"))
