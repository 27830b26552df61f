"""The annotator's workbench on the server (issue 15): finished annotations
are read-only until reopened, a reviewer fixes a mask before accepting, undo
histories are kept on the server, and who else is on a frame."""

import html
import re
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest

from app.extensions import db
from app.models import User, utcnow
from app.models.annotations import EditHistory, FramePresence, GrabCutState
from app.services import labelling
from egonet import io
from tests.app.test_labelling import body, get_png, make_frames, square

BOX = {"box": [40, 25, 125, 95]}
LABELLING_DOC = Path(__file__).resolve().parents[2] / "docs" / "labelling.md"


def signed_in(app, make_user, role: str, name: str):
    client = app.test_client()
    client.login_as(make_user(role, name))
    return client


def test_a_finished_annotation_refuses_every_change_until_its_author_reopens_it(app, make_user):
    f0, f1, _ = make_frames(app)
    ann = signed_in(app, make_user, "annotator", "ann")
    url = f"/api/label/frames/{f1}/annotation"
    done = ann.put(url, json=body(0, square(10, 30, 10, 40), status="done")).get_json()
    assert done["status"] == "done"

    upload = ann.put(f"/api/label/annotations/{done['id']}/instances/0/mask.png?version={done['version']}",
                     data=get_png_bytes(square(0, 9, 0, 9)), content_type="image/png")
    box = ann.post("/api/label/grabcut/box", json={"frame_id": f1, "instance": "k0", **BOX})
    stroke = ann.post("/api/label/grabcut/stroke", json={"frame_id": f1, "instance": "k0", "points": [[50, 50]],
                                                          "label": "fg", "radius": 3})
    ann.put(f"/api/label/frames/{f0}/annotation", json=body(0, square(40, 80, 50, 110)))
    carried = ann.post(f"/api/label/frames/{f0}/propagate", json={"replace": True, "version": done["version"]})
    for refused in (upload, box, stroke, carried):
        assert refused.status_code == 409, refused.get_json()
        assert "reopen" in refused.get_json()["message"]
    assert {upload.get_json()["reason"], box.get_json()["reason"]} == {"finished"}
    still = ann.get(url).get_json()
    assert still["version"] == done["version"] and still["status"] == "done"
    assert np.array_equal(get_png(ann, still["instances"][0]["mask_url"]), square(10, 30, 10, 40))

    # Accepted, then reopened by its author: the acceptance is withdrawn, GrabCut works again.
    rev = signed_in(app, make_user, "reviewer", "rev")
    accepted = rev.post(f"/api/label/annotations/{done['id']}/review", json={"version": done["version"],
                                                                              "decision": "accept"}).get_json()
    assert accepted["status"] == "reviewed"
    assert ann.post(f"{url}/reopen", json={"version": done["version"]}).status_code == 409  # stale
    assert rev.post(f"{url}/reopen", json={"version": accepted["version"]}).status_code == 403  # not a labeller
    reopened = ann.post(f"{url}/reopen", json={"version": accepted["version"]}).get_json()
    assert reopened["status"] == "in_progress" and reopened["reviewer"] == "rev"
    assert ann.post("/api/label/grabcut/box", json={"frame_id": f1, "instance": "k0", **BOX}).status_code == 200
    assert ann.post(f"/api/label/frames/{f0}/annotation/reopen", json={"version": 1}).status_code == 200
    missing = ann.post(f"/api/label/frames/{make_frames(app, n=1, activity='hotel')[0]}/annotation/reopen",
                       json={"version": 0})
    assert missing.status_code == 404 and missing.get_json()["fields"] == {"frame_id": "no annotation"}


def get_png_bytes(mask: np.ndarray) -> bytes:
    from egonet import io

    return io.encode_png(mask)


def test_a_reviewer_fixes_a_done_mask_then_accepts_the_fix(app, make_user):
    frame_id, other_id, _ = make_frames(app)
    ann = signed_in(app, make_user, "annotator", "ann")
    rev = signed_in(app, make_user, "reviewer", "rev")
    url = f"/api/label/frames/{frame_id}/annotation"
    done = ann.put(url, json=body(0, square(40, 80, 50, 100), status="done", time_spent_delta_s=30)).get_json()
    fix_url = f"/api/label/annotations/{done['id']}"
    fixed_mask = square(40, 80, 50, 110)
    fix = body(done["version"], fixed_mask)

    assert ann.put(fix_url, json=fix).status_code == 403  # annotators fix their own on the labelling page
    assert rev.put(fix_url, json={**fix, "version": done["version"] - 1}).status_code == 409
    assert rev.put(fix_url, json={**fix, "status": "done"}).get_json()["fields"] == {"status": "unknown field"}
    # The reviewer's GrabCut sessions are their own, on the author's instance key.
    assert rev.post("/api/label/grabcut/box", json={"frame_id": frame_id, "instance": "k0", **BOX}).status_code == 200
    fixed = rev.put(fix_url, json=fix).get_json()
    assert (fixed["author"], fixed["status"], fixed["fixed_by"]) == ("ann", "done", "rev") and fixed["fixed_at"]
    assert fixed["version"] == done["version"] + 1 and fixed["time_spent_s"] == pytest.approx(30)
    assert np.array_equal(get_png(rev, fixed["instances"][0]["mask_url"]), fixed_mask)
    assert ann.get(url).get_json()["fixed_by"] == "rev"  # the author sees who fixed it

    # The decision goes on the fixed version; the reviewer's sessions go with it.
    stale = rev.post(f"{fix_url}/review", json={"version": done["version"], "decision": "accept"})
    assert stale.status_code == 409
    accepted = rev.post(f"{fix_url}/review", json={"version": fixed["version"], "decision": "accept"}).get_json()
    assert accepted["status"] == "reviewed" and accepted["reviewer"] == "rev" and accepted["fixed_by"] == "rev"
    with app.app_context():
        assert db.session.execute(db.select(GrabCutState)).scalars().all() == []
    assert rev.put(fix_url, json=body(accepted["version"], fixed_mask)).status_code == 409  # no longer done

    # Nobody fixes their own annotation in review, admins included.
    boss = signed_in(app, make_user, "admin", "boss")
    own = boss.put(f"/api/label/frames/{other_id}/annotation", json=body(0, square(0, 5, 0, 5), status="done"))
    refused = boss.put(f"/api/label/annotations/{own.get_json()['id']}", json=body(own.get_json()["version"]))
    assert refused.status_code == 403 and "labelling page" in refused.get_json()["message"]


def test_the_undo_history_is_kept_on_the_server_per_person_and_version(app, make_user):
    frame_id, *_ = make_frames(app)
    ann = signed_in(app, make_user, "annotator", "ann")
    saved = ann.put(f"/api/label/frames/{frame_id}/annotation", json=body(0, square(0, 5, 0, 5))).get_json()
    url = saved["history_url"]
    assert ann.get(url).status_code == 404
    blob = bytes(range(256)) * 40  # opaque to the server (the page sends gzip)

    def put(client, version, data=blob):
        return client.put(f"{url}?version={version}", data=data, content_type="application/gzip")

    assert put(ann, saved["version"] + 1).status_code == 409
    assert put(ann, None).status_code == 400
    assert put(ann, saved["version"]).status_code == 204
    with ann.get(url) as got:
        assert got.data == blob and got.headers["X-Annotation-Version"] == str(saved["version"])
    big = put(ann, saved["version"], b"x" * (labelling.MAX_HISTORY_BYTES + 1))
    assert big.status_code == 413 and "history" in big.get_json()["fields"]
    assert signed_in(app, make_user, "annotator", "bob").get(url).status_code == 404  # each person's own
    assert put(signed_in(app, make_user, "annotator", "carl"), saved["version"]).status_code == 403

    # A newer version: the stored history stays, with the version it ends at, for the page to bridge.
    again = ann.put(f"/api/label/frames/{frame_id}/annotation", json=body(saved["version"], square(0, 9, 0, 9),
                                                                          status="done")).get_json()
    with ann.get(url) as got:
        assert got.headers["X-Annotation-Version"] == str(saved["version"])
    rev = signed_in(app, make_user, "reviewer", "rev")
    assert put(rev, again["version"]).status_code == 204  # a reviewer fixing it keeps theirs
    assert put(ann, again["version"], b"").status_code == 204  # empty: forget it
    assert ann.get(url).status_code == 404
    assert put(ann, again["version"]).status_code == 204
    rev.post(f"/api/label/annotations/{saved['id']}/review", json={"version": again["version"], "decision": "accept"})
    # Accepted: the reviewer's history goes, the author's stays for when they reopen the frame.
    with app.app_context():
        kept = db.session.execute(db.select(User.username, EditHistory.data).join(User, EditHistory.user_id == User.id))
        assert [tuple(row) for row in kept] == [("ann", blob)]


def test_who_else_is_on_a_frame_and_next_unlabelled_skips_frames_others_have_open(app, make_user):
    f1, f2, f3 = make_frames(app)
    ann = signed_in(app, make_user, "annotator", "ann")
    bob = signed_in(app, make_user, "annotator", "bob")

    def presence(client, frame_id, open_=True):
        return client.post(f"/api/label/frames/{frame_id}/presence", json={"open": open_}).get_json()

    assert presence(ann, f1) == {"others": [], "ttl_s": labelling.PRESENCE_TTL_S}
    others = presence(bob, f1)["others"]
    assert [(o["username"], o["status"], o["here"]) for o in others] == [("ann", "open", True)]
    with bob.get(f"/label/next?after={f3}") as response:  # wraps to f1, which ann has open: f2
        assert response.location.endswith(f"/label/frames/{f2}")
    presence(bob, f1, open_=False)
    with ann.get("/label/next") as response:
        assert response.location.endswith(f"/label/frames/{f1}")  # one's own open frame is not skipped

    # ann saves: she has it in progress; bob sees since when.
    saved = ann.put(f"/api/label/frames/{f1}/annotation", json=body(0, square(0, 5, 0, 5))).get_json()
    [held] = presence(bob, f1)["others"]  # bob opens it anyway: the page warns him
    assert (held["username"], held["status"], held["here"]) == ("ann", "in_progress", True)
    assert held["since"] <= held["last_seen"] and saved["updated_at"] <= held["last_seen"]

    # A tab that stopped saying so no longer counts; leaving says so at once.
    presence(ann, f2)
    with app.app_context():
        db.session.execute(db.update(FramePresence).values(seen_at=utcnow() - timedelta(seconds=labelling.PRESENCE_TTL_S + 5)))
        db.session.commit()
    assert presence(bob, f2)["others"] == []
    presence(ann, f3)
    assert [o["username"] for o in presence(bob, f3)["others"]] == ["ann"]
    presence(ann, f3, open_=False)
    assert presence(bob, f3)["others"] == []
    with app.app_context():
        bob_user = db.session.execute(db.select(User).filter_by(username="bob")).scalar_one()
        assert labelling.next_unlabelled(bob_user) == f2  # f1 is ann's in progress; f2 no longer open
    assert bob.post(f"/api/label/frames/{f1}/presence", json={}).get_json()["fields"] == {"open": "is required"}


def documented_shortcuts() -> list[tuple[str, str]]:
    """The rows of the shortcut table in docs/labelling.md."""
    text = LABELLING_DOC.read_text()
    table = text[text.index("| key | does |"):]
    rows = []
    for line in table.splitlines()[2:]:
        if not line.startswith("|"):
            break
        key, does = (cell.strip() for cell in line.strip("|").split("|"))
        rows.append((key.replace("`", ""), does))
    return rows


def test_the_shortcuts_overlay_and_the_labelling_doc_list_the_same_keys(app, make_user):
    frame_id, *_ = make_frames(app, n=1)
    page = signed_in(app, make_user, "annotator", "ann").get(f"/label/frames/{frame_id}").get_data(as_text=True)
    overlay = page[page.index('id="shortcuts"'):]
    overlay = overlay[:overlay.index("</dl>")]
    shown = [(html.unescape(k).strip(), html.unescape(d).strip())
             for k, d in re.findall(r"<dt>(.*?)</dt>\s*<dd>(.*?)</dd>", overlay, re.S)]
    assert len(shown) > 20
    assert documented_shortcuts() == shown


def test_mark_done_sent_twice_is_answered_as_done(app, make_user):
    frame_id, *_ = make_frames(app)
    ann = signed_in(app, make_user, "annotator", "ann")
    url = f"/api/label/frames/{frame_id}/annotation"
    saved = ann.put(url, json=body(0, square(10, 30, 10, 40))).get_json()
    done = body(saved["version"], square(10, 30, 10, 40), status="done")
    first = ann.put(url, json=done).get_json()
    assert first["status"] == "done" and first["version"] == saved["version"] + 1
    # The same click again, on the version it was sent from or the one it made: done, not a conflict.
    for version in (saved["version"], first["version"]):
        again = ann.put(url, json={**done, "version": version})
        assert again.status_code == 200, again.get_json()
        assert (again.get_json()["status"], again.get_json()["version"]) == ("done", first["version"])
    # Other content is a real conflict, and still refused.
    changed = ann.put(url, json=body(saved["version"], square(10, 30, 10, 50), status="done"))
    assert changed.status_code == 409 and changed.get_json()["current_version"] == first["version"]
    assert ann.put(url, json=body(first["version"], square(10, 30, 10, 40))).get_json()["reason"] == "finished"


def test_strokes_work_on_any_mask_starting_from_it(app, make_user):
    """A mask painted by hand, a reviewer's fix and the author's mask after acceptance: no box needed."""
    from tests.app.test_labelling import rle

    frame_id, *_ = make_frames(app)
    ann = signed_in(app, make_user, "annotator", "ann")
    rev = signed_in(app, make_user, "reviewer", "rev")
    painted = square(45, 75, 55, 122)  # most of the red object (rows 40-80, columns 50-110) and some green
    stroke = {"frame_id": frame_id, "instance": "k0", "points": [[116, 60]], "label": "bg", "radius": 4}

    def strokes(client, start):
        return client.post("/api/label/grabcut/stroke", json={**stroke, "start": None if start is None else rle(start)})

    assert strokes(ann, None).get_json()["fields"] == {"box": "no box yet for this object"}
    empty = strokes(ann, np.zeros_like(painted))
    assert empty.status_code == 400 and empty.get_json()["fields"] == {"start": "empty or the whole frame"}
    with strokes(ann, painted) as response:
        assert response.status_code == 200, response.get_json()
        mask = io.decode_mask(response.data)
    # Started from the mask as it is: the background stroke took the green out, the red object stayed.
    red = painted & square(40, 80, 50, 110)
    assert not mask[60, 116] and (mask & red).sum() > 0.9 * red.sum(), (mask & red).sum()
    assert not (mask & ~square(40, 80, 50, 124)).any()
    # The session now exists: a later stroke continues it (start ignored), undo steps back to the mask.
    assert ann.post("/api/label/grabcut/undo", json={"frame_id": frame_id, "instance": "k0"}).status_code == 200

    url = f"/api/label/frames/{frame_id}/annotation"
    done = ann.put(url, json=body(0, painted, status="done")).get_json()
    # The reviewer fixing it has no session of it: their stroke starts from the mask too.
    with strokes(rev, painted) as response:
        assert response.status_code == 200 and not io.decode_mask(response.data)[60, 116]
    rev.post(f"/api/label/annotations/{done['id']}/review", json={"version": done["version"], "decision": "accept"})
    with app.app_context():
        assert db.session.execute(db.select(GrabCutState)).scalars().all() == []  # accepted: every session went
    reopened = ann.post(f"{url}/reopen", json={"version": done["version"] + 1}).get_json()
    assert reopened["status"] == "in_progress"
    with strokes(ann, painted) as response:
        assert response.status_code == 200 and not io.decode_mask(response.data)[60, 116]
