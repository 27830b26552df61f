"""Request bodies checked against a schema at the boundary.

A schema is a dict of field name -> field type. ``json_body(schema)`` parses
the request's JSON and returns plain Python values, or raises a 400 Problem
whose ``fields`` name every bad field (``"clicks[2].x": "must be >= 0"``).
Unknown fields are refused, so a misspelt option never does nothing.

Integers fit a SQL INTEGER column unless a field says otherwise, so an id
past ``app.limits.MAX_ID`` is a 400, not a database error.

Example::

    CLICK = Obj({"x": Float(min=0), "y": Float(min=0)})
    data = json_body({"clicks": List(CLICK, max_len=50), "none": Bool(default=False)})
"""

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from flask import request

from app.errors import Problem
from app.limits import MAX_ID
from egonet.io import decode_json

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
    if not text:
        return None
    try:
        return Int(min=min, max=max).check(int(text))
    except ValueError:
        raise Problem(f"{name}: must be an integer", fields={name: "must be an integer"}) from None
    except Invalid as exc:
        raise Problem(f"{name}: {exc.message}", fields={name: exc.message}) from None


def request_json() -> Any:
    """The request's body decoded by ``egonet.io.decode_json`` (the one JSON reader), None when empty.

    Raises:
        Problem: 400 naming the body when it is not JSON (or nests too deep).
    """
    data = request.get_data(cache=True)
    if not data:
        return None
    if not request.is_json:
        raise Problem("the request body is not JSON (Content-Type: application/json)", fields={"body": "not valid JSON"})
    try:
        return decode_json(data)
    except ValueError as exc:
        raise Problem(f"the request body is not valid JSON: {exc}", fields={"body": "not valid JSON"}) from None


def json_body(schema: dict[str, Field]) -> dict:
    """The request's JSON body, validated (see module doc)."""
    data = request_json()
    return validate(schema, data if data is not None else {})
