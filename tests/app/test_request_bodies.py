"""What a request's body may cost before anyone has decided to read it.

Every JSON body up to MAX_CONTENT_LENGTH (64 MiB) was once decoded by a global
before_request hook, for any address and anyone: a 64 MiB ``[[],[],...]``
posted anonymously to /login took 6.6-8 s and 1.9 GB in one gunicorn
worker. Now only a view marked ``@takes_json(limit)`` reads JSON, after the
access check and at most its limit; every other address answers a JSON body
415 without reading a byte of it.
"""

import inspect
import io
import time
import tracemalloc

import pytest

from app.models import Role
from app.security import access_of
from app.validation import MIB

JSON = {"Accept": "application/json"}


class GeneratedBody(io.RawIOBase):
    """``size`` bytes of ``[],[],[],...`` made as they are read (nothing is held), counting what was read."""

    UNIT = b"[]," * 2**16

    def __init__(self, size: int):
        self.size, self.position, self.consumed = size, 0, 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:  # the test client measures the body by seeking to its end
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        self.position = offset if whence == 0 else self.size + offset if whence == 2 else self.position + offset
        return self.position

    def tell(self) -> int:
        return self.position

    def readinto(self, buffer) -> int:
        n = min(len(buffer), self.size - self.position, len(self.UNIT) - 3)
        start = self.position % 3
        buffer[:n] = self.UNIT[start:start + n]
        self.position += n
        self.consumed += n
        return n


def post_generated(client, url, size, *, method="POST", chunked=False, content_type="application/json"):
    """Send a generated body: with its Content-Length, or chunked (no length: read until it ends)."""
    body = GeneratedBody(size)
    headers, environ = dict(JSON), {}
    if chunked:
        headers["Transfer-Encoding"] = "chunked"
        environ = {"CONTENT_LENGTH": "", "wsgi.input_terminated": True}
    response = client.open(url, method=method, input_stream=body, content_type=content_type, headers=headers,
                           environ_overrides=environ)  # fmt: skip
    return response, body


@pytest.mark.parametrize("url", ["/login", "/s/", "/s/o/AbCdEfGhIjKlMnOpQrStUvWx"])
def test_a_64_mib_json_body_to_a_form_address_is_refused_unread(app, client, monkeypatch, url):
    def decode_json(data):
        raise AssertionError("a form address decoded a JSON body")

    monkeypatch.setattr("app.validation.decode_json", decode_json)
    client.fetch_csrf_token()
    tracemalloc.start()
    started = time.perf_counter()
    try:
        response, body = post_generated(client, url, 64 * MIB)
        took = time.perf_counter() - started
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    with response:
        assert response.status_code == 415, response.data[:300]
        assert response.get_json()["error"] == "unsupported_media_type"
    assert body.consumed == 0, f"{body.consumed} bytes of the body were read"
    assert took < 5.0 and peak < 8 * MIB, (took, peak)


def json_views(app):
    for rule in app.url_map.iter_rules():
        view = app.view_functions[rule.endpoint]
        yield rule, view, getattr(view, "json_limit", None)


def test_json_is_read_only_by_views_that_say_so(app):
    """A view that calls json_body carries @takes_json (else JSON to it would be a 415), and only those."""
    marked = {rule.endpoint for rule, _, limit in json_views(app) if limit is not None}
    reading = {rule.endpoint for rule, view, _ in json_views(app) if rule.endpoint != "static" and "json_body(" in inspect.getsource(view)}
    assert marked == reading and len(marked) >= 17
    limits = {rule.endpoint: limit for rule, _, limit in json_views(app) if limit is not None}
    assert max(limits.values()) == limits["label.save_annotation"] == limits["label.fix_annotation"] == 8 * MIB
    assert sum(v < MIB for v in limits.values()) >= 0.75 * len(limits)  # most need well under 1 MiB


def test_every_other_address_answers_json_with_415(app, admin_client):
    refused = 0
    for rule, view, limit in json_views(app):
        allowed = access_of(view)
        if limit is not None or rule.endpoint == "static" or not (allowed is None or Role.ADMIN in allowed):
            continue
        values = {name: sorted(getattr(rule._converters[name], "items", ["1"]))[0] for name in rule.arguments}
        url = rule.build(values, append_unknown=False)[1]
        for method in sorted(rule.methods - {"HEAD", "OPTIONS"}):
            with admin_client.open(url, method=method, json={"a": 1}, headers=JSON) as response:
                assert response.status_code == 415, (method, url, response.status_code)
                refused += 1
    assert refused > 60


@pytest.mark.parametrize("chunked", [False, True])
def test_json_over_a_view_s_limit_is_a_413_naming_it(admin_client, chunked):
    for url, method, limit in [("/api/label/frames/1/annotation", "PUT", 8 * MIB), ("/api/label/frames/1/presence", "POST", 64 * 1024)]:
        response, body = post_generated(admin_client, url, limit + 1, method=method, chunked=chunked)
        with response:
            assert response.status_code == 413, (url, response.data[:300])
            answer = response.get_json()
            assert answer["error"] == "too_large" and answer["limit"] == limit and str(limit) in answer["message"]
            assert answer["fields"] == {"body": f"over {limit} bytes"}
        # With a Content-Length nothing is read; without one, no more than the limit and a byte.
        assert body.consumed == ((limit + 1) if chunked else 0)


def test_json_up_to_the_limit_is_read(admin_client):
    body = b'{"open": true}'
    padded = body + b" " * (64 * 1024 - len(body))
    with admin_client.post("/api/label/frames/1/presence", data=padded, content_type="application/json", headers=JSON) as response:
        assert response.status_code == 404 and "frame" in response.get_json()["message"]  # read and validated: no such frame


def test_json_from_someone_not_allowed_is_refused_unread(app, client):
    client.fetch_csrf_token()
    response, body = post_generated(client, "/api/label/frames/1/annotation", 4 * MIB, method="PUT")
    with response:
        assert response.status_code == 401
    assert body.consumed == 0


def test_a_json_view_refuses_another_type_of_body_unread(admin_client):
    response, body = post_generated(admin_client, "/api/label/frames/1/annotation", 1000, method="PUT", content_type="text/plain")
    with response:
        assert response.status_code == 415 and response.get_json()["fields"] == {"body": "not JSON"}
    assert body.consumed == 0
