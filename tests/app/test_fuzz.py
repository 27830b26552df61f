"""Bad input never costs a 500: every endpoint of the URL map, fuzzed.

For each role, hypothesis sends every state-changing endpoint (and every
GET) malformed JSON, wrong types, huge numbers and strings, missing fields,
coordinates far outside the frame, and random form fields, with ids in the
path that are real, zero, negative or past what an id column holds. Any
500 fails. New routes are fuzzed automatically.

Then every route gets, for each role, the bytes PostgreSQL and the database
layer refuse: NUL and unpaired surrogates in every string a request can carry
(path, query, headers, form fields and their names, file names, uploaded
JSON, JSON strings and keys), and query integers past what any column holds
(the names come from the app's source, so a new parameter is covered too).
Such text is refused (4xx, never a 2xx), and nothing answers 500.
"""

import inspect
import io
import json
import re
from pathlib import Path
from urllib.parse import quote

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from werkzeug.routing import AnyConverter

from app import IdConverter
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
UNSAFE = ["a\x00b", "\ud800", "x\udfffy"]  # NUL and unpaired surrogates
scalars = st.none() | st.booleans() | st.integers() | HUGE | st.floats(allow_nan=False) | st.text(max_size=300) | st.sampled_from(UNSAFE)
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


# 2**63, the least integer past a BIGINT, goes to each name on its own (a 400 for one name hides the
# others); the rest go to every name at once.
OUT_OF_RANGE = ["9223372036854775808", "99999999999999999999", "-9223372036854775809", "1" * 5000]
# Query parameters the app reads, from its source (a new one is fuzzed without listing it here).
QUERY_READERS = re.compile(r"""(?:query_ints?|args\.get|args\.getlist|source\.get|source\[|args\[)\(?["'](\w+)["']""")
SOURCE = "\n".join(p.read_text() for p in Path(__file__).resolve().parents[2].glob("app/**/*.py"))
QUERY_NAMES = sorted(set(QUERY_READERS.findall(SOURCE)) | {"PROLIFIC_PID", "workerId", "assignmentId", "external_id", "STUDY_ID"})


def query(pairs: dict[str, str]) -> str:
    """A query string as a client may send it (a surrogate goes as its UTF-8 bytes, which werkzeug decodes leniently)."""
    return "&".join(f"{quote(k, errors='surrogatepass')}={quote(v, errors='surrogatepass')}" for k, v in pairs.items())


def unsafe_bodies(view):
    """(kwargs for client.open, whether it carries unsafe text) for a view's state-changing methods."""
    if getattr(view, "json_limit", None) is not None:
        for value in UNSAFE:
            yield {"data": json.dumps({value: 1}), "content_type": "application/json"}, True
            yield {"data": json.dumps({name: value for name in FIELDS}), "content_type": "application/json"}, True
            yield {"data": json.dumps({name: [{"label": value, "key": value}] for name in FIELDS}), "content_type": "application/json"}, True
        yield {"data": b'{"label": "\xed\xa0\x80"}', "content_type": "application/json"}, True  # a surrogate in UTF-8
        return
    yield {"data": {name: "a\x00b" for name in FIELDS}}, True
    yield {"data": {"a\x00b": "x"}}, True
    definition = json.dumps({"name": "\ud800", "activities": ["a\x00b"]}).encode()
    yield {"data": {"definition": (io.BytesIO(definition), "study.json")}, "content_type": "multipart/form-data"}, False
    yield {"data": {"definition": (io.BytesIO(b"{}"), "a\x00b.json")}, "content_type": "multipart/form-data"}, True


@pytest.mark.slow
# Admins reach every staff view (annotators' and reviewers' routes are theirs too), participants theirs, and
# anonymous clients the public ones: three roles reach every view, and the text rule runs before any of them.
@pytest.mark.parametrize("role", ["anonymous", "admin", "participant"])
def test_no_route_takes_unsafe_text_or_answers_500_to_huge_integers(app, client, make_user, tmp_path, role):
    values = all_url_values(app, tmp_path)
    user = None if role == "anonymous" else make_user(role, f"bytes-{role}")
    checked = 0

    def send(url, method="GET", *, unsafe, **kwargs):
        nonlocal checked
        if user is not None:
            client.login_as(user)
        with client.open(url, method=method, headers={"Accept": "application/json", **kwargs.pop("headers", {})}, **kwargs) as response:
            status = response.status_code
            assert status < 500, f"{role} {method} {url} {kwargs}: {status} {response.get_data()[:300]!r}"
            assert not (unsafe and status < 300), f"{role} {method} {url} {kwargs}: {status} took unsafe text"
        checked += 1

    for rule in app.url_map.iter_rules():
        if rule.endpoint == "auth.logout":
            continue
        view = app.view_functions[rule.endpoint]
        url = rule.build(values, append_unknown=False)[1]
        methods = sorted(rule.methods - {"HEAD", "OPTIONS"})
        for name in [n for n, c in rule._converters.items() if not isinstance(c, IdConverter | AnyConverter)]:  # text, not ids or choices
            for value in ("a\x00b", "%00", "%ED%A0%80"):  # a surrogate's bytes in a URL are decoded to U+FFFD, which is safe
                bad = rule.build({**values, name: "PLACEHOLDER"}, append_unknown=False)[1].replace("PLACEHOLDER", quote(value, safe="%"))
                send(bad, methods[0], unsafe="0" in value)
        if "GET" in methods:
            module = inspect.getsource(inspect.getmodule(view))
            names = [n for n in QUERY_NAMES if f'"{n}"' in module] or QUERY_NAMES[:5]
            for value in UNSAFE:
                send(f"{url}?{query({n: value for n in QUERY_NAMES})}", unsafe="\x00" in value)
                send(f"{url}?{query({value: '1'})}", unsafe="\x00" in value)
            send(url, headers={"User-Agent": "a\x00b", "X-Requested-With": "a\x00b"}, unsafe=True)
            for name in names:
                send(f"{url}?{query({name: OUT_OF_RANGE[0]})}", unsafe=False)
            for value in OUT_OF_RANGE[1:]:
                send(f"{url}?{query(dict.fromkeys(QUERY_NAMES, value))}", unsafe=False)
        for method in methods:
            if method == "GET":
                continue
            for kwargs, unsafe in unsafe_bodies(view):
                send(url, method, unsafe=unsafe, **kwargs)
            send(f"{url}?{query({n: OUT_OF_RANGE[0] for n in QUERY_NAMES})}", method, unsafe=False)
    assert checked > 500
