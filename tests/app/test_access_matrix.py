"""Role x route -> status, for every rule in the app's URL map.

The rules live per area in tests/app/access/. Every endpoint must be named
there: a new route that is not fails ``test_every_route_is_in_the_matrix``,
so none can escape the check.
"""

import pytest

from tests.app.access import ALL, all_url_values, core, label, scores, studies, training

AREAS = (core, label, studies, training, scores)
EXPECTED = {endpoint: rule for area in AREAS for endpoint, rule in area.RULES.items()}


def test_every_route_is_in_the_matrix(app):
    missing = sorted({r.endpoint for r in app.url_map.iter_rules()} - EXPECTED.keys())
    assert not missing, f"add these endpoints to tests/app/access/: {missing}"


@pytest.fixture
def url_values(app, tmp_path):
    return all_url_values(app, tmp_path)


@pytest.mark.parametrize("role", [None, *sorted(ALL)])
def test_role_route_matrix(app, client, make_user, url_values, role):
    user = make_user(role) if role is not None else None
    if user is not None:
        client.login_as(user)
    for rule in app.url_map.iter_rules():
        allowed, status = EXPECTED[rule.endpoint]
        url = rule.build(url_values, append_unknown=False)[1]
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
