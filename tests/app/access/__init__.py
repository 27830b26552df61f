"""Access rules per area, merged by tests/app/test_access_matrix.py.

Each module defines ``RULES`` (endpoint -> (roles allowed or None for
public, status: one, or one per method)) and ``url_values(app, tmp_path)``,
which creates what its routes need and returns the URL values
(``{"frame_id": 3, ...}``) to build them with.
"""

from app.models import Role

STAFF = frozenset({Role.ADMIN, Role.ANNOTATOR, Role.REVIEWER})
ALL = STAFF | {Role.PARTICIPANT}
ADMIN = frozenset({Role.ADMIN})


def all_url_values(app, tmp_path) -> dict:
    """URL values from every area (each creates the objects its routes need)."""
    from tests.app.access import core, label, scores, studies, training

    values: dict = {}
    for area in (core, label, studies, training, scores):
        values.update(area.url_values(app, tmp_path))
    return values
