"""egonet.io.decode_json: a linear pre-scan, the depth limit, and the unsafe-text rule.

The pre-scan once stripped strings with a backtracking regex: ``["`` and N
escaped quotes (an unterminated string) cost O(N^2), 32 KB about 3 s and a
mebibyte about an hour. Every shape below is a mebibyte and must be decided
in well under a second; the answers must be json.loads's.
"""

import json
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from egonet.io import MAX_JSON_DEPTH, UnsafeText, decode_json, json_depth

MIB = 2**20
# Shapes that cost the old scan O(N^2) or stress the new one: escape runs, quotes, brackets.
PATHOLOGICAL = {
    "unterminated string of escaped quotes": b'["' + b'\\"' * (MIB // 2 - 1),
    "escaped quotes, then closed": b'["' + b'\\"' * (MIB // 2 - 4) + b'"]',
    "many short strings": b"[" + b'"a",' * (MIB // 4 - 1) + b'"a"]',
    "many strings of brackets": b"[" + b'"[{",' * (MIB // 5 - 1) + b'"]}"]',
    "one long run of backslashes": b'["' + b"\\" * (MIB - 4) + b'"]',
    "odd backslash runs before quotes": b'["' + b'\\\\\\"' * (MIB // 4 - 1) + b'"]',
    "unterminated backslashes": b'["' + b"\\" * (MIB - 2),
    "deep nesting": b"[" * MIB,
    "deep nesting inside a string": b'["' + b"[" * (MIB - 4) + b'"]',
    "deep nesting after an escaped quote": b'["\\"' + b"[" * (MIB - 4),
    "empty lists": b"[" + b"[]," * (MIB // 3 - 1) + b"[]]",
    "objects at the limit": b'{"a":' * MAX_JSON_DEPTH + b"1" + b"}" * MAX_JSON_DEPTH,
}


def outcome(decode, body: bytes):
    try:
        return "ok", decode(body)
    except RecursionError:
        return "recursion", None
    except ValueError as exc:
        return "error", "nested deeper" in str(exc)


@pytest.mark.parametrize("name", PATHOLOGICAL)
def test_pathological_mebibytes_are_decided_fast_and_as_json_loads_decides(name):
    body = PATHOLOGICAL[name]
    started = time.perf_counter()
    ours = outcome(decode_json, body)
    took = time.perf_counter() - started
    # A linear scan takes well under a second here; the old quadratic one took 38 s for 64 KiB and about an
    # hour for 1 MiB. The bound is generous so that a loaded CI machine never fails a linear scan.
    assert took < 10.0, f"{name}: {took:.2f} s for {len(body)} bytes"
    depth = json_depth(body)
    if depth > MAX_JSON_DEPTH:
        assert ours == ("error", True), name  # refused before json.loads could recurse
    else:
        assert ours == outcome(json.loads, body), name


def reference_depth(text: str) -> int:
    """The depth by a plain state machine: a backslash escapes the next character (a quote it escapes is text),
    a quote flips in or out of a string, brackets outside strings nest."""
    depth = deepest = 0
    inside = escaped = False
    for c in text:
        if c == "\\" and not escaped:
            escaped = True
            continue
        was_escaped, escaped = escaped, False
        if c == '"' and not was_escaped:
            inside = not inside
        elif not inside and c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif not inside and c in "]}":
            depth -= 1
    return deepest


def nesting(value) -> int:
    if isinstance(value, list):
        return 1 + max(map(nesting, value), default=0)
    if isinstance(value, dict):
        return 1 + max(map(nesting, value.values()), default=0)
    return 0


texts = st.text(alphabet='[]{}"\\ a,:é', max_size=400)
json_values = st.recursive(st.none() | st.integers() | st.text(alphabet='[]{}"\\ aé\n'),
                           lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(alphabet='[]"\\a'), inner, max_size=4),
                           max_leaves=40)


@settings(max_examples=400, deadline=None)
@given(text=texts)
def test_depth_equals_a_reference_state_machine(text):
    data = text.encode()
    assert json_depth(data) == reference_depth(text)


def test_depth_is_carried_across_the_scan_s_pieces():
    """The scan works a mebibyte at a time: a string, an escape run or nesting across the boundary."""
    for pad in (MIB - 3, MIB - 2, MIB - 1, MIB):
        text = "[" + " " * (pad - 1) + '"\\\\\\"[[[" , [[' + "]]]"
        assert json_depth(text.encode()) == reference_depth(text) == 3, pad


@settings(max_examples=300, deadline=None)
@given(value=json_values)
def test_depth_of_valid_json_is_its_nesting_and_decoding_round_trips(value):
    text = json.dumps(value, ensure_ascii=False)
    assert json_depth(text.encode()) == nesting(value)
    assert decode_json(text.encode()) == value == decode_json(text)


@pytest.mark.parametrize("body, field", [
    ('{"\\ud800": 1}', "(a key)"),
    ('{"a": ["ok", "x\\u0000y"]}', "a[1]"),
    ('[{"label": "\\udfff"}]', "[0].label"),
    ('{"a": {"b\\u0000": 1}}', "a"),
])
def test_nul_and_unpaired_surrogates_are_refused_where_they_are(body, field):
    with pytest.raises(UnsafeText) as caught:
        decode_json(body.encode())
    assert caught.value.field == field


def test_paired_surrogates_and_escaped_backslashes_are_text():
    assert decode_json(b'{"e": "\\ud83d\\ude00", "b": "\\\\u0000"}') == {"e": "\U0001f600", "b": "\\u0000"}
    assert decode_json('["\U0001f600"]'.encode("utf-16")) == ["\U0001f600"]
