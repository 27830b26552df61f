"""region cap: studies made before the cap on a region's share of the frame keep their regions (max_region_share 1.0)

Revision ID: 0015
Revises: 0014

A data change only: each hierarchical study's recorded region settings get
``max_region_share: 1.0`` (no cap), so its masks stay what they were; new
studies record the cap they are made with (0.25 by default).
"""

import json

from alembic import op
import sqlalchemy as sa

revision = "0015"
down_revision = "0014"
branch_labels = None
depends_on = None

studies = sa.table("study", sa.column("id", sa.Integer), sa.column("superpixels", sa.JSON))


def _rewrite(change):
    bind = op.get_bind()
    for study_id, settings in bind.execute(sa.select(studies.c.id, studies.c.superpixels)).all():
        settings = json.loads(settings) if isinstance(settings, str) else dict(settings or {})
        if settings.get("method", "hierarchical") == "hierarchical" and change(settings):
            bind.execute(studies.update().where(studies.c.id == study_id).values(superpixels=settings))


def upgrade():
    _rewrite(lambda s: "max_region_share" not in s and s.setdefault("max_region_share", 1.0) == 1.0)


def downgrade():
    _rewrite(lambda s: s.pop("max_region_share", None) is not None)
