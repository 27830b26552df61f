import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.errors import Problem
from app.validation import Bool, Float, Int, List, Obj, Str, validate

CLICK = Obj({"x": Float(min=0, max=1279), "y": Float(min=0, max=959)})
SCHEMA = {
    "clicks": List(CLICK, max_len=3),
    "none": Bool(default=False),
    "label": Str(choices={"fg", "bg"}),
    "radius": Int(min=1, max=200),
    "note": Str(max_len=5, default=None, nullable=True),
}


def fields_of(data):
    with pytest.raises(Problem) as info:
        validate(SCHEMA, data)
    assert info.value.status == 400
    return info.value.fields


def test_valid_body_with_defaults():
    data = validate(SCHEMA, {"clicks": [{"x": 1, "y": 2.5}], "label": "fg", "radius": 3.0})
    assert data == {"clicks": [{"x": 1.0, "y": 2.5}], "none": False, "label": "fg", "radius": 3, "note": None}


def test_every_bad_field_is_named():
    fields = fields_of({"clicks": [{"x": -1, "y": "a"}, {"x": 1}], "label": "up", "radius": True, "extra": 1})
    assert fields == {
        "clicks[0].x": "must be >= 0",
        "clicks[0].y": "must be a number",
        "clicks[1].y": "is required",
        "label": "must be one of bg, fg",
        "radius": "must be an integer",
        "extra": "unknown field",
    }


def test_non_finite_huge_and_wrong_container():
    assert fields_of({"clicks": [{"x": float("inf"), "y": 1}], "label": "fg", "radius": 1}) == {
        "clicks[0].x": "must be a finite number"
    }
    assert fields_of({"clicks": {}, "label": "fg", "radius": 10**30}) == {"clicks": "must be a list", "radius": "must be <= 200"}
    with pytest.raises(Problem, match="JSON object"):
        validate(SCHEMA, [1, 2])


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=20,
)


@given(st.dictionaries(st.sampled_from(["clicks", "none", "label", "radius", "note", "zzz"]), json_values))
def test_any_json_gives_a_result_or_a_400(data):
    try:
        validate(SCHEMA, data)
    except Problem as exc:
        assert exc.status == 400 and exc.fields
