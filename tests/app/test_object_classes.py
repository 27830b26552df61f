"""The project's object classes (page, CLI, strict setting) and hand instances, which are no action-object."""

import numpy as np
import pytest

from app.extensions import db
from app.models import Role, User
from app.services.labelling.classes import add_classes, class_names
from tests.app.test_labelling import body, get_png, make_frames, square


def test_the_cli_lists_adds_and_removes_classes(app, runner):
    added = runner.invoke(args=["egonet", "classes", "add", "cup", "Frying pan", "CUP", "  knife  "])
    assert added.exit_code == 0, added.output
    assert "added 3 of 4: cup, Frying pan, knife" in added.output
    assert runner.invoke(args=["egonet", "classes", "list"]).output.splitlines() == ["cup", "Frying pan", "knife"]
    assert runner.invoke(args=["egonet", "classes", "remove", "frying PAN"]).exit_code == 0
    assert runner.invoke(args=["egonet", "classes", "list"]).output.splitlines() == ["cup", "knife"]
    missing = runner.invoke(args=["egonet", "classes", "remove", "spoon"])
    assert missing.exit_code != 0 and "the class list has no 'spoon'" in missing.output
    long = runner.invoke(args=["egonet", "classes", "add", "x" * 121])
    assert long.exit_code != 0 and "1 to 120 characters" in long.output


def test_only_admins_manage_the_list_from_its_page(app, client, make_user):
    client.login_as(make_user("annotator", "ann"))
    assert client.get("/label/classes").status_code in (302, 403)
    assert client.post("/label/classes", data={"names": "cup"}).status_code in (302, 403)
    with app.app_context():
        assert class_names() == []
    client.login_as(make_user("admin", "boss"))
    page = client.get("/label/classes")
    assert page.status_code == 200 and b"No classes yet" in page.data
    assert client.post("/label/classes", data={"names": "cup, pan\nknife\n\n"}).status_code == 302
    page = client.get("/label/classes").get_data(as_text=True)
    assert all(f'data-class="{n}"' in page for n in ("cup", "pan", "knife"))
    assert client.post("/label/classes/remove", data={"name": "pan"}).status_code == 302
    with app.app_context():
        assert class_names() == ["cup", "knife"]
    assert client.post("/label/classes", data={"names": " , "}).status_code == 400
    assert client.post("/label/classes/remove", data={"name": "spoon"}).status_code == 404


def test_the_label_field_completes_from_the_list(app, client, make_user):
    frame_id, *_ = make_frames(app)
    with app.app_context():
        add_classes(["cup", "knife"])
    client.login_as(make_user("annotator", "ann"))
    page = client.get(f"/label/frames/{frame_id}").get_data(as_text=True)
    assert '<datalist id="object-classes"><option value="cup"><option value="knife"><option value="hand"' in page


@pytest.mark.parametrize("strict", [False, True])
def test_a_label_outside_the_list_is_saved_or_refused_as_the_setting_says(app_with, make_user, strict):
    app = app_with(LABEL_CLASSES_STRICT=strict)
    frame_id, *_ = make_frames(app)
    client = app.test_client()
    with app.app_context():
        add_classes(["cup"])
        user = User(username="ann", role=Role.ANNOTATOR)
        db.session.add(user)
        db.session.commit()
        client.login_as(user)
    url = f"/api/label/frames/{frame_id}/annotation"
    request = body(0, square(10, 30, 10, 40), square(50, 60, 50, 60))
    request["instances"][0]["label"] = "Cup"  # the list's name in another case: always fine
    request["instances"][1]["label"] = "saucer"
    answer = client.put(url, json=request)
    if strict:
        assert answer.status_code == 400
        assert answer.get_json()["fields"] == {"instances[1].label": "not in the class list"}
        request["instances"][1]["label"] = "hand"  # always allowed
        assert client.put(url, json=request).status_code == 200
    else:
        assert answer.status_code == 200
        assert [i["label"] for i in answer.get_json()["instances"]] == ["Cup", "saucer"]


def test_a_hand_instance_is_no_part_of_the_action_object_mask(app, client, make_user):
    frame_id, *_ = make_frames(app)
    client.login_as(make_user("annotator", "ann"))
    url = f"/api/label/frames/{frame_id}/annotation"
    cup, hand = square(10, 30, 10, 40), square(60, 100, 20, 60)
    request = body(0, cup, hand)
    request["instances"][0].update(kind="tactile", label="cup")
    request["instances"][1].update(label="Hand ")
    saved = client.put(url, json=request).get_json()
    assert [i["label"] for i in saved["instances"]] == ["cup", "Hand"]
    assert np.array_equal(get_png(client, saved["mask_url"]), cup)
    # Hands alone with "no action-object" are a finished frame: the hands are not an action-object.
    only_hands = body(saved["version"], hand, no_action_object=True, status="done")
    only_hands["instances"][0]["label"] = "hand"
    done = client.put(url, json=only_hands)
    assert done.status_code == 200, done.get_json()
    assert done.get_json()["mask_url"] is None and done.get_json()["status"] == "done"
