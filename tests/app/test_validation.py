import io

import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.errors import Problem
from app.validation import Bool, Float, Int, List, Obj, Str, validate
from egonet.io import MAX_JSON_DEPTH, decode_json

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


DEEP = b'{"clicks": ' + b"[" * 50_000 + b"]" * 50_000 + b"}"


def test_deeply_nested_json_is_a_fast_400_naming_the_body_or_file(app, client, admin_client, runner, tmp_path):
    """A decoder that recursed answered 500 (RecursionError); every JSON reader now refuses depth up front."""
    from app.extensions import db
    from app.models.studies import Participant
    from app.services import studies
    from tests.app.access.studies import build_study

    with app.app_context():
        ids = build_study(tmp_path / "data", frames=2, per_activity=1, participants=1)
        participant = db.session.get(Participant, ids["participants"][0])
        studies.answer_consent(participant, agree=True)
        studies.start_session(participant)
        trial_id, code = studies.session_state(participant).trial.id, participant.code
    json_header = {"Accept": "application/json"}
    upload = admin_client.post("/studies/import", data={"definition": (io.BytesIO(DEEP), "deep.json")},
                               content_type="multipart/form-data", headers=json_header)  # fmt: skip
    assert upload.status_code == 400 and upload.get_json()["fields"] == {"definition": "not valid JSON"}
    admin_put = client.put("/api/label/frames/1/annotation", data=DEEP, content_type="application/json", headers=json_header)
    client.post("/s/", data={"code": code})  # now the participant
    participant_post = client.post(f"/s/api/trials/{trial_id}", data=DEEP, content_type="application/json", headers=json_header)
    for response in (admin_put, participant_post):
        assert response.status_code == 400, response.data[:300]
        assert response.get_json()["fields"] == {"body": "not valid JSON"} and "nested deeper" in response.get_json()["message"]
    (tmp_path / "deep.json").write_bytes(DEEP)
    result = runner.invoke(args=["egonet", "study-create", str(tmp_path / "deep.json")])
    assert result.exit_code == 1 and "nested deeper than 100 levels" in result.output


def test_decode_json_reads_strings_as_text_and_counts_depth_exactly():
    assert decode_json('{"a": "[[[{{{", "b": "\\"]]"}') == {"a": "[[[{{{", "b": '"]]'}
    assert decode_json(b"[" * MAX_JSON_DEPTH + b"]" * MAX_JSON_DEPTH) is not None
    for deeper in ("[" * (MAX_JSON_DEPTH + 1) + "]" * (MAX_JSON_DEPTH + 1), '[{"a": ' * 60 + "1" + "}]" * 60):
        with pytest.raises(ValueError, match="nested deeper"):
            decode_json(deeper)
    with pytest.raises(ValueError):
        decode_json("[}")
