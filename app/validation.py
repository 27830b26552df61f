"""Request bodies checked against a schema at the boundary.

A schema is a dict of field name -> field type. ``json_body(schema)`` parses
the request's JSON and returns plain Python values, or raises a 400 Problem
whose ``fields`` name every bad field (``"clicks[2].x": "must be >= 0"``).
Unknown fields are refused, so a misspelt option never does nothing.

Integers fit a SQL INTEGER column unless a field says otherwise, so an id
past ``app.limits.MAX_ID`` is a 400, not a database error; so do the query's
(``query_int``, ``query_ints``).

A view reads a JSON body only when it says so with ``@takes_json(max_bytes)``
(the body's limit, sized to its schema); ``check_request`` answers a JSON body
sent anywhere else with 415 without reading it, and one over the limit with
413. It also holds every string a request carries (path, query, headers, form
fields and file names; ``decode_json`` does JSON's strings and keys) to one
rule: no NUL and no unpaired surrogate (``egonet.io.UNSAFE_TEXT``), a 400.

Example::

    CLICK = Obj({"x": Float(min=0), "y": Float(min=0)})

    @bp.post("/answer")
    @takes_json(64 * KIB)
    def answer():
        data = json_body({"clicks": List(CLICK, max_len=50), "none": Bool(default=False)})
"""

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

from flask import current_app, request

from app.errors import Problem
from app.limits import MAX_ID
from egonet.io import UNSAFE_REASON, UNSAFE_TEXT, UnsafeText, decode_json

KIB, MIB = 1024, 1024**2

MISSING = object()


class Invalid(Problem):
    """A value that does not fit its field, said in a few words (``must be >= 0``):
    whoever checks the value names the field."""


@dataclass(kw_only=True)
class Field:
    default: Any = MISSING
    nullable: bool = False

    def check(self, value: Any) -> Any:  # pragma: no cover - overridden
        raise NotImplementedError


@dataclass
class Int(Field):
    min: int | None = -MAX_ID - 1
    max: int | None = MAX_ID

    def check(self, value):
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise Invalid("must be an integer")
        _check_range(value, self.min, self.max)
        return value


@dataclass
class Float(Field):
    min: float | None = None
    max: float | None = None

    def check(self, value):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise Invalid("must be a number")
        try:
            value = float(value)
        except OverflowError:  # an integer past 1e308
            raise Invalid("must be a finite number") from None
        if not math.isfinite(value):
            raise Invalid("must be a finite number")
        _check_range(value, self.min, self.max)
        return value


@dataclass
class Str(Field):
    min_len: int = 0
    max_len: int = 10_000
    choices: Iterable[str] | None = None

    def check(self, value):
        if not isinstance(value, str):
            raise Invalid("must be a string")
        if not self.min_len <= len(value) <= self.max_len:
            raise Invalid(f"must have {self.min_len}-{self.max_len} characters")
        if self.choices is not None and value not in self.choices:
            raise Invalid(f"must be one of {', '.join(sorted(self.choices))}")
        return value


@dataclass
class Bool(Field):
    def check(self, value):
        if not isinstance(value, bool):
            raise Invalid("must be true or false")
        return value


@dataclass
class List(Field):
    item: Field = None
    min_len: int = 0
    max_len: int = 10_000

    def check(self, value):
        if not isinstance(value, list):
            raise Invalid("must be a list")
        if not self.min_len <= len(value) <= self.max_len:
            raise Invalid(f"must have {self.min_len}-{self.max_len} items")
        return value  # items are checked by _parse, which knows their paths


@dataclass
class Obj(Field):
    fields: dict[str, Field] = field(default_factory=dict)

    def check(self, value):
        if not isinstance(value, dict):
            raise Invalid("must be an object")
        return value


def _check_range(value, low, high) -> None:
    if low is not None and value < low:
        raise Invalid(f"must be >= {low}")
    if high is not None and value > high:
        raise Invalid(f"must be <= {high}")


def _parse(spec: Field, value: Any, path: str, errors: dict[str, str]) -> Any:
    if value is None:
        if spec.nullable:
            return None
        errors[path] = "must not be null"
        return None
    try:
        value = spec.check(value)
    except Invalid as exc:
        errors[path] = exc.message
        return None
    if isinstance(spec, List):
        return [_parse(spec.item, v, f"{path}[{i}]", errors) for i, v in enumerate(value)]
    if isinstance(spec, Obj):
        return parse_object(spec.fields, value, errors, prefix=f"{path}.")
    return value


def parse_object(schema: dict[str, Field], data: dict, errors: dict[str, str], *, prefix: str = "") -> dict:
    out = {}
    for name in data.keys() - schema.keys():
        errors[f"{prefix}{name}"] = "unknown field"
    for name, spec in schema.items():
        if name not in data:
            if spec.default is MISSING:
                errors[f"{prefix}{name}"] = "is required"
            else:
                out[name] = spec.default
            continue
        out[name] = _parse(spec, data[name], f"{prefix}{name}", errors)
    return out


def validate(schema: dict[str, Field], data: Any) -> dict:
    """Check decoded JSON against ``schema``; raise a 400 Problem naming the bad fields."""
    if not isinstance(data, dict):
        raise Problem("the request body must be a JSON object", fields={"body": "must be a JSON object"})
    errors: dict[str, str] = {}
    out = parse_object(schema, data, errors)
    if errors:
        first = next(iter(sorted(errors)))
        raise Problem(f"invalid field {first}: {errors[first]}", fields=dict(sorted(errors.items())))
    return out


def query_int(name: str, *, min: int | None = 1, max: int | None = MAX_ID) -> int | None:
    """The query parameter ``name`` as an integer (an id, by default), or
    None when it is absent or empty.

    Raises:
        Problem: 400 naming ``name`` when it is not such an integer.
    """
    text = request.args.get(name, "")
    return _int_of(name, text, min, max) if text else None


def query_ints(name: str, *, min: int = 1, max: int = MAX_ID) -> list[int]:
    """Every value of the query parameter ``name`` (``?runs=3&runs=5``, or ``3,5``) as integers (ids by default).

    Raises:
        Problem: 400 naming ``name`` when one is not such an integer.
    """
    return [_int_of(name, part, min, max) for text in request.args.getlist(name) for part in text.split(",") if part.strip()]


def _int_of(name: str, text: str, low: int | None, high: int | None) -> int:
    try:
        if not text.isascii():
            raise ValueError
        value = int(text)
    except ValueError:
        raise Problem(f"{name}: must be an integer", fields={name: "must be an integer"}) from None
    try:
        return Int(min=-MAX_ID - 1 if low is None else low, max=MAX_ID if high is None else high).check(value)
    except Invalid as exc:
        raise Problem(f"{name}: {exc.message}", fields={name: exc.message}) from None


def takes_json(max_bytes: int = 64 * KIB) -> Callable[[Callable], Callable]:
    """Mark a view as taking a JSON body of at most ``max_bytes`` (which ``json_body`` reads)."""

    def decorate(view: Callable) -> Callable:
        view.json_limit = max_bytes
        return view

    return decorate


def json_limit() -> int | None:
    """The JSON body limit of the request's view (None: it takes no JSON)."""
    view = current_app.view_functions.get(request.endpoint) if request.endpoint else None
    return getattr(view, "json_limit", None)


def _has_body() -> bool:
    return bool(request.content_length or request.headers.get("Transfer-Encoding"))


def _too_large(limit: int, field: str) -> Problem:
    return Problem(f"{field}: larger than the {limit} bytes this address takes", status=413,
                   fields={field: f"over {limit} bytes"}, limit=limit)


def read_body(limit: int, *, field: str = "body") -> bytes:
    """The request's body, reading at most ``limit`` bytes.

    Raises:
        Problem: 413 naming ``field`` and the limit, from Content-Length or once more than the limit arrives.
    """
    if (request.content_length or 0) > limit:
        raise _too_large(limit, field)
    chunks, size = [], 0
    while size <= limit and (chunk := request.stream.read(limit + 1 - size)):  # a read may return less
        chunks.append(chunk)
        size += len(chunk)
    if size > limit:
        raise _too_large(limit, field)
    return b"".join(chunks)


def json_body(schema: dict[str, Field]) -> dict:
    """The request's JSON body (an empty one is ``{}``), decoded by ``egonet.io.decode_json`` (the one JSON
    reader) and validated (see module doc); at most the view's ``takes_json`` limit is read.

    Raises:
        Problem: 400 naming the body when it is not JSON (or nests too deep), or the field at fault (unsafe
            text, or the schema's); 413 over the limit; 415 for a body of another type (unread).
    """
    limit = json_limit()
    if limit is None:
        raise RuntimeError(f"{request.endpoint} reads a JSON body without @takes_json")
    if not request.is_json and _has_body():
        raise Problem("the request body is not JSON (Content-Type: application/json)", status=415, fields={"body": "not JSON"})
    data = read_body(limit)
    try:
        doc = decode_json(data) if data else {}
    except UnsafeText as exc:
        raise Problem(f"invalid field {exc.field}: {UNSAFE_REASON}", fields={exc.field: UNSAFE_REASON}) from None
    except ValueError as exc:
        raise Problem(f"the request body is not valid JSON: {exc}", fields={"body": "not valid JSON"}) from None
    return validate(schema, doc)


def check_text(field: str, value: str) -> None:
    """Refuse ``UNSAFE_TEXT`` (NUL, unpaired surrogates) in a string from a request, with a 400 naming ``field``."""
    if UNSAFE_TEXT.search(value):
        raise Problem(f"{field}: {UNSAFE_REASON}", fields={field: UNSAFE_REASON})


def check_request() -> None:
    """before_request hook, after the access check: a JSON body only for a ``takes_json`` view (else 415,
    unread) and within its limit (else 413, unread); no unsafe text in the path, query, headers or form."""
    if request.endpoint is None:  # 404 and 405 are answered by Flask itself
        return
    if request.is_json and _has_body():
        limit = json_limit()
        if limit is None:
            raise Problem("this address takes no JSON body", status=415, fields={"body": "JSON is not accepted here"})
        if (request.content_length or 0) > limit:
            raise _too_large(limit, "body")
    check_text("path", request.path)
    for name, value in request.headers.items():
        check_text("header", name + value)
    for where, pairs in (("query", request.args), ("form", request.form), ("file", request.files)):
        for key, value in pairs.items(multi=True):
            check_text(where, key)
            check_text(key, value if isinstance(value, str) else value.filename or "")
