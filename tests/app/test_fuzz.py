"""Bad input never costs a 500: every endpoint of the URL map, fuzzed.

For each role, hypothesis sends every state-changing endpoint (and every
GET) malformed JSON, wrong types, huge numbers and strings, missing fields,
coordinates far outside the frame, and random form fields, with ids in the
path that are real, zero, negative or past what an id column holds. Any
500 fails. New routes are fuzzed automatically.
"""

import json
import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.app.access import all_url_values

FIELDS = [
    "x", "y", "x0", "y0", "x1", "y1", "points", "label", "radius", "clicks", "none", "version",
    "status", "kind", "instances", "comment", "events", "rt_ms", "name", "activities", "seed",
    "frames_per_activity", "time_limit_min", "sigma", "model", "epochs", "mask", "no_action_object",
    "time_spent_s", "decision", "window", "type", "t", "count", "code", "username", "password",
    "frame_id", "instance", "box", "size", "counts", "active", "q0", "PROLIFIC_PID", "workerId", "assignmentId",
    "time_zone", "screen", "pixel_ratio", "definition", "display_mode", "conditions", "comprehension",
]
HUGE = st.sampled_from([10**30, -(10**30), 1e308, -1e308, 10**400, 2**63, 2**31, -1, 0, 1e-300, 99999999])
# A path id: the real one (None), or one that no row can have.
PATH_IDS = st.none() | st.sampled_from([2**31 - 1, 2**31, 2**63, 2**64, 10**30, 0, -1])
scalars = st.none() | st.booleans() | st.integers() | HUGE | st.floats(allow_nan=False) | st.text(max_size=300)
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.sampled_from(FIELDS), inner, max_size=5), max_leaves=25)
objects = st.dictionaries(st.sampled_from(FIELDS) | st.text(max_size=10), values, max_size=8)
RAW = [b"{", b"null", b"[]", b'"x"', b'{"x": NaN}', b'{"x": Infinity, "y": -Infinity}', b'{"x": 1e999}',
       b"\xff\xfe\x00garbage", b'{"clicks": [{"x": 1e12, "y": -5}]}', b'{"points": []}', b"x" * 20000,
       b'{"clicks": ' + b"[" * 50_000 + b"]" * 50_000 + b"}", b'{"points": ' + b'[{"x": ' * 5_000 + b"1" + b"}]" * 5_000 + b"}"]
bodies = st.one_of(
    objects.map(lambda o: ("json", json.dumps(o).encode())),
    st.sampled_from(RAW).map(lambda b: ("json", b)),
    st.dictionaries(st.sampled_from(FIELDS), st.text(max_size=50), max_size=6).map(lambda d: ("form", d)),
    st.binary(max_size=200).map(lambda b: ("png", b)),
)
queries = st.dictionaries(st.sampled_from(FIELDS + ["page", "activity", "runs", "studies", "format", "after", "STUDY_ID", "external_id"]),
                          st.text(max_size=20) | st.integers().map(str) | HUGE.map(str), max_size=3)


@pytest.mark.slow
@pytest.mark.parametrize("role", ["admin", "annotator", "reviewer", "participant"])
@settings(max_examples=3, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_no_endpoint_answers_500(app, client, make_user, tmp_path_factory, role, data):
    if not hasattr(app, "_fuzz_values"):
        app._fuzz_values = all_url_values(app, tmp_path_factory.mktemp("fuzz"))
        app._fuzz_user = make_user(role, f"fuzz-{role}")
    values = app._fuzz_values
    for rule in app.url_map.iter_rules():
        if rule.endpoint in ("static", "auth.logout"):
            continue
        ids = {name: data.draw(PATH_IDS) for name in re.findall(r"<int:(\w+)>", rule.rule)}
        url = rule.build({**values, **{name: v for name, v in ids.items() if v is not None}}, append_unknown=False)[1]
        for method in sorted(rule.methods - {"HEAD", "OPTIONS"}):
            client.login_as(app._fuzz_user)
            if method == "GET":
                response = client.get(url, query_string=data.draw(queries))
            else:
                kind, body = data.draw(bodies)
                if kind == "form":
                    response = client.open(url, method=method, data=body)
                else:
                    ctype = "image/png" if kind == "png" else "application/json"
                    response = client.open(url, method=method, data=body, content_type=ctype,
                                           headers={"Accept": "application/json"})
            with response:
                assert response.status_code < 500, f"{role} {method} {url}: {response.status_code} {response.get_data()[:300]!r}"
