"""The security review's reproductions of 500s from bytes a client can send (issue 32, point 6).

NUL characters (which PostgreSQL refuses), unpaired surrogates (not Unicode)
and query integers past a BIGINT each answered 500 somewhere. One rule in
app.validation (and egonet.io.decode_json for JSON) now refuses such text in
every string before any query; every query integer is bounded; link tokens
are checked by the URL map. Run on PostgreSQL too (EGONET_TEST_POSTGRES_URL):
that is where the NULs failed.
"""

import io
import json

import pytest
from sqlalchemy import event

from app.extensions import db
from app.models import Role
from app.models.studies import Participant
from app.services import studies
from egonet.io import UNSAFE_REASON
from tests.app.access import label as label_access
from tests.app.access import studies as studies_access
from tests.app.conftest import PASSWORD

JSON = {"Accept": "application/json"}


def answer(response) -> tuple[int, dict]:
    with response:
        return response.status_code, response.get_json()


def refused(response, field: str) -> bool:
    status, body = answer(response)
    return status == 400 and body["fields"] == {field: UNSAFE_REASON}


def test_nul_in_a_form_field_or_a_link_is_refused_anonymously(app, client):
    assert refused(client.post("/login", data={"username": "a\x00b", "password": "x"}, headers=JSON), "username")
    assert refused(client.post("/s/", data={"code": "ABCD\x00EFG"}, headers=JSON), "code")
    for url in ("/s/l/a%00b", "/s/o/a%00b", "/s/o/a%00b/example", "/s/l/" + "a" * 65):
        for method in ("GET", "POST"):
            assert answer(client.open(url, method=method, headers=JSON))[0] == 404, (method, url)  # not a token: no query
    assert refused(client.get("/login?next=/a%00b", headers=JSON), "next")
    assert refused(client.get("/login", headers={**JSON, "User-Agent": "a\x00b"}), "header")


def test_access_codes_are_checked_against_their_alphabet_before_any_query(ctx):
    from app.extensions import db as database

    statements = []
    record = lambda *args: statements.append(args[2])  # noqa: E731
    event.listen(database.engine, "before_cursor_execute", record)
    try:
        for code in ("ＡＢＣＤ-ＥＦＧＨ", "OOOO-0000", "ÀBCD-EFGH", "abcd-efg1"):  # full-width, look-alikes, accents, a 1
            assert studies.participant_by_code(code) is None
        assert statements == []
        assert studies.participant_by_code("ABCD-EFGH") is None and statements  # a code of the alphabet is looked up
    finally:
        event.remove(database.engine, "before_cursor_execute", record)


def test_nul_and_surrogates_in_labels_comments_names_and_definitions_are_refused(app, admin_client, tmp_path, runner):
    values = label_access.url_values(app, tmp_path)
    frame_id, annotation_id = values["frame_id"], values["annotation_id"]
    instance = {"key": "a", "label": "a\x00b", "mask": {"size": [1, 1], "counts": [1]}}
    save = admin_client.put(f"/api/label/frames/{frame_id}/annotation", json={"version": 0, "instances": [instance]}, headers=JSON)
    assert refused(save, "instances[0].label")
    instance["label"] = "\ud800"
    fix = admin_client.put(f"/api/label/annotations/{annotation_id}", data=json.dumps({"version": 1, "instances": [instance]}),
                           content_type="application/json", headers=JSON)  # fmt: skip
    assert refused(fix, "instances[0].label")
    review = admin_client.post(f"/api/label/annotations/{annotation_id}/review",
                               json={"version": 1, "decision": "reject", "comment": "bad\x00"}, headers=JSON)  # fmt: skip
    assert refused(review, "comment")
    user = admin_client.post("/users/", data={"username": "a\x00b", "password": PASSWORD, "role": Role.ANNOTATOR.value}, headers=JSON)
    assert refused(user, "username")
    for definition in ({"name": "a\x00b"}, {"\udc00": 1}):
        upload = admin_client.post("/studies/import", data={"definition": (io.BytesIO(json.dumps(definition).encode()), "s.json")},
                                   content_type="multipart/form-data", headers=JSON)  # fmt: skip
        assert refused(upload, "definition")
        (tmp_path / "s.json").write_text(json.dumps(definition))
        result = runner.invoke(args=["egonet", "study-create", str(tmp_path / "s.json")])
        assert result.exit_code == 1 and UNSAFE_REASON in result.output
    named = admin_client.post("/studies/import", data={"definition": (io.BytesIO(b"{}"), "s\x00.json")},
                              content_type="multipart/form-data", headers=JSON)  # fmt: skip
    assert refused(named, "definition")
    weights = admin_client.post("/training/weights/uploads", data=json.dumps({"\ud800": 1}), content_type="application/json", headers=JSON)
    assert refused(weights, "(a key)")
    weights = admin_client.post("/training/weights/uploads", json={"filename": "w\x00.caffemodel", "size": 10}, headers=JSON)
    assert refused(weights, "filename")


def test_surrogates_from_a_participant_are_refused(app, client, tmp_path):
    with app.app_context():
        ids = studies_access.build_study(tmp_path / "data", frames=2, per_activity=1, participants=1)
        participant = db.session.get(Participant, ids["participants"][0])
        studies.answer_consent(participant, agree=True)
        studies.start_session(participant)
        trial_id, code = studies.session_state(participant).trial.id, participant.code
    client.post("/s/", data={"code": code})
    for body in ('{"\\ud800": 1}', '{"clicks": [], "events": [{"kind": "\\udfff", "t_ms": 1}]}', b'{"time_zone": "\xed\xa0\x80"}'):
        url = "/s/api/environment" if "time_zone" in str(body) else f"/s/api/trials/{trial_id}"
        status, answered = answer(client.post(url, data=body, content_type="application/json", headers=JSON))
        assert status == 400 and list(answered["fields"].values()) == [UNSAFE_REASON], (body, answered)


@pytest.mark.parametrize("path, name", [
    ("/frames/{frame_id}/points.bin?prediction=9223372036854775808", "prediction"),
    ("/frames/{frame_id}/points.bin?max=99999999999999999999", "max"),
    ("/activities/{activity_id}?page=99999999999999999999", "page"),
    ("/studies/{study_id}/frames?page=99999999999999999999", "page"),
    ("/training/status?ids=1,9223372036854775808", "ids"),
    ("/scores/table.csv?chosen=1&runs=99999999999999999999", "runs"),
    ("/api/label/frames/{frame_id}/filmstrip?at=-9223372036854775809", "at"),
])
def test_query_integers_past_a_column_are_a_400_naming_them(app, admin_client, tmp_path, path, name):
    values = label_access.url_values(app, tmp_path)
    with app.app_context():
        values["activity_id"] = db.session.get(label_access.Frame, values["frame_id"]).sequence.activity_id
    if "{study_id}" in path:
        with app.app_context():
            values["study_id"] = studies_access.build_study(tmp_path / "s", frames=1, per_activity=1, participants=1)["study"]
    status, body = answer(admin_client.get(path.format(**values), headers=JSON))
    assert status == 400 and list(body["fields"]) == [name], body
