"""Role x route -> status, for every rule in the app's URL map.

EXPECTED must name every endpoint: a new route that is not listed here fails
``test_every_route_is_in_the_matrix``, so none can escape the check.
"""

import pytest

from app.models import Role
from app.services.importing import import_path
from tests.app.factories import image_folder

STAFF = {Role.ADMIN, Role.ANNOTATOR, Role.REVIEWER}
ALL = STAFF | {Role.PARTICIPANT}

# endpoint -> (roles allowed, status for them: one, or one per method).
# Bodies are empty, so a POST that needs a form answers 400.
EXPECTED = {
    "static": (None, 200),
    "auth.login": (None, {"GET": 200, "POST": 400}),
    "auth.logout": (ALL, 302),
    "frames.index": (STAFF, 200),
    "frames.activity": (STAFF, 200),
    "frames.frame": (STAFF, 200),
    "frames.thumbnail": (STAFF, 200),
    "frames.depth": (STAFF, 200),
    "frames.media_file": (STAFF, 200),
    "api.activities": (STAFF, 200),
    "api.activity_frames": (STAFF, 200),
    "api.frame": (STAFF, 200),
}


def rules(app):
    return [r for r in app.url_map.iter_rules()]


def test_every_route_is_in_the_matrix(app):
    missing = sorted({r.endpoint for r in rules(app)} - EXPECTED.keys())
    assert not missing, f"add these endpoints to EXPECTED: {missing}"


@pytest.fixture
def dataset(app, tmp_path):
    from app.extensions import db
    from app.models import Activity, Frame

    with app.app_context():
        import_path(image_folder(tmp_path / "rec", n=2, depth=True), activity="cooking")
        frame = db.session.execute(db.select(Frame)).scalars().first()
        activity = db.session.execute(db.select(Activity)).scalar_one()
        return {"frame_id": frame.id, "activity_id": activity.id, "name": frame.rgb_path, "filename": "css/app.css"}


@pytest.mark.parametrize("role", [None, *sorted(ALL)])
def test_role_route_matrix(app, client, make_user, dataset, role):
    user = make_user(role) if role is not None else None
    if user is not None:
        client.login_as(user)
    for rule in rules(app):
        allowed, status = EXPECTED[rule.endpoint]
        url = rule.build(dataset, append_unknown=False)[1]
        for method in sorted(rule.methods - {"HEAD", "OPTIONS"}):
            with client.open(url, method=method) as response:
                got = response.status_code
            if allowed is None or (role is not None and role in allowed):
                expected = {status[method] if isinstance(status, dict) else status}
            elif role is None:
                expected = {401} if url.startswith("/api/") else {302}
            else:
                expected = {403}
            assert got in expected, f"{role} {method} {url}: {got}, expected {expected}"
            if rule.endpoint == "auth.logout" and user is not None:
                client.login_as(user)
