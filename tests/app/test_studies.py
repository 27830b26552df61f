"""Study builder, participants, cached superpixels, soft masks, exports, admin pages and CLI."""

import csv
import io
import json
import random
import zipfile
from datetime import UTC, datetime

import cv2
import numpy as np
import pytest
from flask import current_app

from app.extensions import db
from app.models import Activity, Frame, Sequence, Status
from app.models.studies import EntryKind, EventKind, Outcome, Participant, Study, Trial
from app.services import ground_truth, studies
from egonet import clicks as egonet_clicks
from tests.app.access.studies import build_study


def answer_all(participant: Participant, *, every=None):
    """Consent, start and answer every trial; ``every(trial)`` gives the Answer (default: one click)."""
    studies.answer_consent(participant, agree=True)
    studies.start_session(participant)
    state = studies.session_state(participant)
    while state.trial is not None:
        answer = every(state.trial) if every else studies.Answer(clicks=[(5.0 + state.trial.position, 7.0, 321.0)])
        state = studies.submit(participant, state.trial, answer)
    return state


# --------------------------------------------------------------------------
# Builder


def test_sampling_is_reproducible_from_the_seed_and_only_eligible(ctx, tmp_path):
    ids = build_study(tmp_path, frames=6, per_activity=3, participants=0, seed=11)
    # Make two cooking frames ineligible: one back in progress, one rejected.
    cooking = db.session.execute(db.select(Activity).filter_by(name="cooking")).scalar_one()
    frames = db.session.execute(db.select(Frame).join(Sequence).where(Sequence.activity_id == cooking.id).order_by(Frame.index)).scalars().all()
    frames[0].annotations[0].status = Status.IN_PROGRESS
    frames[1].annotations[0].status = Status.REJECTED
    db.session.commit()
    counts = {a.name: n for a, n in studies.eligible_counts()}
    assert counts == {"cooking": 4, "hotel": 6}

    def draw(seed):
        study = studies.create_study(name=f"s{seed}", activity_ids=ids["activities"], frames_per_activity=4, seed=seed)
        return [sf.frame_id for sf in study.frames], study

    first, study = draw(5)
    again, _ = draw(5)
    assert first == again  # same seed, same eligible frames: same draw
    assert len(first) == 8 and len(set(first)) == 8
    assert {frames[0].id, frames[1].id}.isdisjoint(first)  # never ineligible frames
    by_activity = [db.session.get(Frame, f).sequence.activity.name for f in first]
    assert by_activity == ["cooking"] * 4 + ["hotel"] * 4
    others = {tuple(draw(seed)[0]) for seed in range(6, 12)}
    assert len(others) > 1  # the seed matters
    assert study.seed == 5 and study.superpixels == studies.DEFAULT_SUPERPIXELS
    assert [sf.position for sf in study.frames] == list(range(1, 9))

    # The recorded seed reproduces the draw with the documented recipe.
    hotel = db.session.execute(db.select(Activity).filter_by(name="hotel")).scalar_one()
    eligible_hotel = [f for f in ground_truth.labelled_frames([hotel.id])]
    expected = [f.id for f in random.Random("5:hotel").sample(eligible_hotel, 4)]
    assert first[4:] == expected


def test_builder_refuses_bad_settings_naming_the_field(ctx, tmp_path):
    ids = build_study(tmp_path, frames=2, per_activity=1, participants=0)
    acts = ids["activities"]
    cases = [
        (dict(activity_ids=acts, frames_per_activity=3), "frames_per_activity", "cooking has 2"),
        (dict(activity_ids=[]), "activities", "at least one"),
        (dict(activity_ids=[999]), "activities", "unknown"),
        (dict(activity_ids=acts, time_limit_s=0), "time_limit_s", None),
        (dict(activity_ids=acts, trial_limit_s=-1), "trial_limit_s", None),
        (dict(activity_ids=acts, sigma_px=0), "sigma_px", None),
        (dict(activity_ids=acts, seed=-3), "seed", None),
        (dict(activity_ids=acts, superpixels={"method": "mcg"}), "superpixel_method", None),
        (dict(activity_ids=acts, superpixels={"method": "slic", "scale": 3}), "scale", "does not apply"),
        (dict(activity_ids=acts, superpixels={"method": "slic", "n_segments": 2.5}), "n_segments", None),
        (dict(activity_ids=acts, superpixels={"method": "felzenszwalb", "max_side": 4}), "max_side", None),
    ]
    for kwargs, field, words in cases:
        kwargs.setdefault("frames_per_activity", 1)
        with pytest.raises(studies.StudyProblem) as info:
            studies.create_study(name="x", **kwargs)
        assert info.value.field == field, kwargs
        if words:
            assert words in str(info.value)
    with pytest.raises(studies.StudyProblem, match="name"):
        studies.create_study(name="  ", activity_ids=acts, frames_per_activity=1)
    felz = studies.create_study(name="f", activity_ids=acts, frames_per_activity=1, superpixels={"method": "felzenszwalb", "max_side": None})
    assert felz.superpixels == {"method": "felzenszwalb", "scale": 100.0, "min_size": 50, "max_side": None}
    assert 0 <= studies.create_study(name="r", activity_ids=acts, frames_per_activity=1).seed < 2**31


def test_participants_get_codes_links_and_seeded_orders(ctx, tmp_path):
    ids = build_study(tmp_path, frames=4, per_activity=4, participants=3)
    study = db.session.get(Study, ids["study"])
    links = studies.add_participants(study, count=2, entry="link")
    people = study.participants
    assert [p.number for p in people] == [1, 2, 3, 4, 5]
    assert [p.user.username for p in people[:2]] == [f"p-{study.id}-001", f"p-{study.id}-002"]
    assert all(p.user.role.value == "participant" and p.user.password_hash is None for p in people)
    assert len({p.code for p in people}) == 5
    assert all(len(p.code) == 8 and set(p.code) <= set(studies.CODE_ALPHABET) for p in people)
    assert [p.link_token is not None for p in people] == [False, False, False, True, True]
    assert all(p.entry is EntryKind.LINK for p in links)
    frame_ids = sorted(sf.id for sf in study.frames)
    orders = []
    for p in people:
        order = [t.study_frame_id for t in p.trials]
        assert sorted(order) == frame_ids and [t.position for t in p.trials] == list(range(1, 9))
        # The recorded order seed reproduces the order.
        expected = [sf.id for sf in study.frames]
        random.Random(p.order_seed).shuffle(expected)
        assert order == expected and p.order_seed == studies.order_seed(study.seed, p.number)
        orders.append(tuple(order))
    assert len(set(orders)) > 1
    for bad, field in ((dict(count=0), "count"), (dict(count=1, entry="email"), "entry")):
        with pytest.raises(studies.StudyProblem) as info:
            studies.add_participants(study, **bad)
        assert info.value.field == field
    assert studies.participant_by_code(studies.format_code(people[0].code).lower()).id == people[0].id
    assert studies.participant_by_code(" " + people[0].code[:4] + " " + people[0].code[4:]).id == people[0].id
    assert studies.participant_by_code("nope") is None and studies.participant_by_code("") is None


# --------------------------------------------------------------------------
# Superpixels and soft masks


def test_superpixels_are_computed_once_and_cached(ctx, tmp_path, monkeypatch):
    ids = build_study(tmp_path, frames=2, per_activity=1, participants=0)
    study = db.session.get(Study, ids["study"])
    frame = study.frames[0].frame
    assert not studies.cached_superpixels(frame, study.superpixels)
    labels = studies.superpixel_labels(frame, study.superpixels)
    assert labels.shape == (frame.height, frame.width) and labels.dtype == np.uint16
    path = studies.masks.labels_path(frame, study.superpixels)
    assert path.exists() and studies.settings_key(study.superpixels) in str(path) and frame.content_hash in path.name
    assert not list(path.parent.glob(".tmp-*"))

    def boom(*args, **kwargs):
        raise AssertionError("superpixels recomputed")

    monkeypatch.setattr(egonet_clicks, "superpixels", boom)
    np.testing.assert_array_equal(studies.superpixel_labels(frame, study.superpixels), labels)
    # Other settings are another cache entry; a damaged file is computed again.
    monkeypatch.undo()
    assert not studies.cached_superpixels(frame, {**study.superpixels, "n_segments": 20})
    path.write_bytes(b"damaged")
    np.testing.assert_array_equal(studies.superpixel_labels(frame, study.superpixels), labels)
    assert studies.precompute_superpixels(study) == 1  # the second frame
    assert studies.precompute_superpixels(study) == 0


def test_soft_masks_follow_egonet_and_the_scorer_interface(ctx, tmp_path):
    ids = build_study(tmp_path, frames=3, per_activity=3, participants=2, sigma_px=9.0)
    study = db.session.get(Study, ids["study"])
    first, second = study.participants

    def answers(trial):
        if trial.position == 2:
            return studies.Answer(clicks=[], none=True)
        if trial.position == 3:
            return studies.Answer(clicks=[(30.0, 20.0, 100.0), (60.0, 40.0, 900.0)])
        return studies.Answer(clicks=[(10.0, 5.0, 400.0)])

    answer_all(first, every=answers)
    answer_all(second)
    db.session.expire_all()

    masks = list(studies.participant_soft_masks(first))
    assert [f.id for f, _ in masks] == [t.frame.id for t in first.trials]
    for (frame, mask), trial in zip(masks, first.trials):
        assert mask.dtype == np.float32 and mask.shape == (frame.height, frame.width)
        if trial.outcome is Outcome.NONE:
            assert not mask.any()
            continue
        labels = studies.superpixel_labels(frame, study.superpixels)
        expected = egonet_clicks.soft_mask(
            (frame.height, frame.width), [(c.x, c.y) for c in trial.clicks], sigma=9.0, labels=labels
        )
        np.testing.assert_array_equal(mask, expected)
        for region in np.unique(labels)[:20]:  # constant on every superpixel
            assert np.ptp(mask[labels == region]) == 0

    assert [p.id for p in studies.study_participants([study.id])] == [first.id, second.id]
    assert studies.study_participants([study.id + 100]) == []

    study_frame = study.frames[0]
    mean, n = studies.mean_soft_mask(study_frame)
    per = [studies.trial_soft_mask(t) for t in studies.answered_trials(study_frame)]
    assert n == 2 and np.allclose(mean, (per[0] + per[1]) / 2)
    with pytest.raises(ValueError, match="no answer"):
        studies.trial_soft_mask(Trial(id=0, outcome=Outcome.EXPIRED))


def test_expired_and_pending_trials_give_no_mask(ctx, tmp_path):
    ids = build_study(tmp_path, frames=2, per_activity=2, participants=1, trial_limit_s=5)
    participant = db.session.get(Participant, ids["participants"][0])
    studies.answer_consent(participant, agree=True)
    studies.start_session(participant)
    state = studies.session_state(participant)
    state.trial.outcome = Outcome.EXPIRED
    db.session.commit()
    state = studies.session_state(participant)  # the next trial: time runs out before any click
    state = studies.submit(participant, state.trial, studies.Answer(clicks=[], timed_out=True))
    studies.submit(participant, state.trial, studies.Answer(clicks=[(3.0, 3.0, 4900.0)], timed_out=True))
    assert [t.outcome for t in participant.trials][:3] == [Outcome.EXPIRED, Outcome.EXPIRED, Outcome.TIMED_OUT]
    masks = list(studies.participant_soft_masks(participant))
    assert [f.id for f, _ in masks] == [participant.trials[2].frame.id] and masks[0][1].max() > 0


# --------------------------------------------------------------------------
# Exports


def done_study(tmp_path):
    """P01 answered every trial (at one frozen instant), P02 only consented."""
    current_app.config["STUDY_CLOCK"] = lambda: datetime(2026, 3, 1, 9, 30, tzinfo=UTC)
    ids = build_study(tmp_path, frames=2, per_activity=2, participants=2)
    study = db.session.get(Study, ids["study"])
    first, second = study.participants

    def with_events(trial):
        return studies.Answer(
            clicks=[(3.0, 4.0, 250.0)],
            rt_ms=600.0,
            events=[studies.ClientEvent(kind=EventKind.BLUR, client_ms=100.0), studies.ClientEvent(kind=EventKind.RESIZE, client_ms=200.0, detail={"width": 800, "height": 600})],
            window_width=1280,
            window_height=900,
            display_width=640.0,
            display_height=480.0,
            pixel_ratio=1.0,
        )

    answer_all(first, every=with_events)
    studies.answer_consent(second, agree=True)  # consented, never started
    return study


def test_exports_csv_json_and_mask_pngs(ctx, tmp_path):
    study = done_study(tmp_path)
    trials = list(csv.DictReader(io.StringIO(studies.export_csv(study, "trials"))))
    assert len(trials) == 8 and list(trials[0]) == studies.TRIAL_COLUMNS
    p1 = [r for r in trials if r["participant"] == "P01"]
    assert [r["outcome"] for r in p1] == ["clicked"] * 4 and all(r["rt_ms"] == "600.0" and r["events"] == "2" for r in p1)
    assert all(r["outcome"] == "pending" for r in trials if r["participant"] == "P02")
    assert p1[0]["window_width"] == "1280" and p1[0]["server_ms"] == "0.0" and p1[0]["shown_at"] == "2026-03-01T09:30:00+00:00"
    clicks = list(csv.DictReader(io.StringIO(studies.export_csv(study, "clicks"))))
    assert len(clicks) == 4 and clicks[0]["x"] == "3.0" and clicks[0]["rt_ms"] == "250.0" and clicks[0]["received_at"]
    events = list(csv.DictReader(io.StringIO(studies.export_csv(study, "events"))))
    assert [e["kind"] for e in events[:2]] == ["blur", "resize"] and json.loads(events[1]["detail"]) == {"width": 800, "height": 600}

    doc = studies.export_json(study)
    assert doc["study"]["seed"] == study.seed and doc["study"]["late_grace_s"] == studies.LATE_GRACE_S
    assert len(doc["frames"]) == 4 and {"content_hash", "activity"} <= set(doc["frames"][0])
    p1_doc = doc["participants"][0]
    assert p1_doc["end_reason"] == "completed" and len(p1_doc["trials"]) == 4
    assert p1_doc["trials"][0]["clicks"][0]["x"] == 3.0 and p1_doc["trials"][0]["events"][1]["detail"]["width"] == 800
    json.dumps(doc)  # serialisable

    files = dict(studies.mask_files(study))
    # P01's trials, a mean and the labels per answered frame, regions.json, the manifest, clicks.csv, the codebook
    assert len(files) == 4 + 4 + 4 + 4
    trial = study.participants[0].trials[0]
    png = files[f"P01/{trial.position:04d}-frame{trial.frame.id}.png"]
    decoded = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    assert decoded.dtype == np.uint16
    np.testing.assert_array_equal(decoded, np.round(studies.trial_soft_mask(trial).astype(np.float64) * 65535).astype(np.uint16))
    manifest = list(csv.DictReader(io.StringIO(files["manifest.csv"].decode())))
    assert len(manifest) == 8 and manifest[-1]["participant"] == "mean" and manifest[-1]["participants"] == "1"

    archive = zipfile.ZipFile(io.BytesIO(b"".join(studies.masks_zip(study))))
    assert sorted(archive.namelist()) == sorted(files) and archive.read("manifest.csv") == files["manifest.csv"]

    out = tmp_path / "export"
    written = studies.export_to_folder(study, out)
    assert (out / "trials.csv").read_text() == studies.export_csv(study, "trials")
    assert (out / "masks" / "manifest.csv").exists() and len(written) == 7 + len(files)  # 4 tables, 2 JSON documents, the codebook


# --------------------------------------------------------------------------
# Admin pages and CLI


def test_admin_creates_a_study_through_the_form(app, admin_client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, frames=3, per_activity=1, participants=0)
    page = admin_client.get("/studies/new")
    assert page.status_code == 200 and b"3 eligible" in page.data and b'name="seed"' in page.data
    form = {
        "name": "pilot",
        "activities": [str(a) for a in ids["activities"]],
        "frames_per_activity": "2",
        "seed": "42",
        "time_limit_minutes": "30",
        "trial_limit_seconds": "",
        "multiple_clicks": "y",
        "sigma_px": "60",
        "superpixel_method": "slic",
        "n_segments": "100",
        "compactness": "10",
        "scale": "",
        "min_size": "",
        "max_side": "640",
        "instructions": "Click the object.\r\n\r\nQuickly.",
        "consent": "You agree.",
    }
    too_many = admin_client.post("/studies/new", data={**form, "frames_per_activity": "5"})
    assert too_many.status_code == 400 and b"cooking has 3" in too_many.data
    missing = admin_client.post("/studies/new", data={**form, "name": "", "activities": []})
    assert missing.status_code == 400 and missing.data.count(b"field-error") >= 2
    created = admin_client.post("/studies/new", data=form)
    assert created.status_code == 302
    with app.app_context():
        study = db.session.execute(db.select(Study).filter_by(name="pilot")).scalar_one()
        assert (study.seed, study.time_limit_s, study.trial_limit_s, study.multiple_clicks) == (42, 1800, None, True)
        assert study.superpixels == {"method": "slic", "n_segments": 100, "compactness": 10.0, "max_side": 640}
        assert study.instructions == "Click the object.\n\nQuickly." and len(study.frames) == 4  # CRLF from browsers
        study_id = study.id
    detail = admin_client.get(created.headers["Location"])
    assert detail.status_code == 200 and b"pilot" in detail.data and b"No participants yet" in detail.data

    bad = admin_client.post(f"/studies/{study_id}/participants", data={"count": "0", "entry": "code"})
    assert bad.status_code == 400
    added = admin_client.post(f"/studies/{study_id}/participants", data={"count": "2", "entry": "link"})
    assert added.status_code == 302
    detail = admin_client.get(f"/studies/{study_id}")
    assert detail.data.count(b'data-participant="P0') == 2 and b"/s/l/" in detail.data and b"not started" in detail.data
    index = admin_client.get("/studies/")
    assert index.status_code == 200 and b"pilot" in index.data


def test_admin_sees_progress_masks_mean_maps_and_exports(app, admin_client, tmp_path):
    with app.app_context():
        study = done_study(tmp_path)
        study_id, first = study.id, study.participants[0]
        first_id, trial_id, sf_id = first.id, first.trials[0].id, first.trials[0].study_frame_id
        frame = first.trials[0].frame
        size = (frame.width, frame.height)
    detail = admin_client.get(f"/studies/{study_id}")
    assert b"completed" in detail.data and b"4 / 4" in detail.data and b"consented" in detail.data
    page = admin_client.get(f"/studies/{study_id}/participants/{first_id}")
    assert page.status_code == 200 and page.data.count(b"/overlay.png") == 4
    assert admin_client.get(f"/studies/{study_id}/frames").data.count(b"/mean.png") == 4
    assert admin_client.get(f"/studies/{study_id}/frames/{sf_id}").status_code == 200
    for url in (f"/studies/{study_id}/trials/{trial_id}/overlay.png", f"/studies/{study_id}/frames/{sf_id}/mean.png?outline=1"):
        response = admin_client.get(url)
        image = cv2.imdecode(np.frombuffer(response.data, np.uint8), cv2.IMREAD_COLOR)
        assert response.mimetype == "image/png" and image.shape[:2] == size[::-1], url
    mask = admin_client.get(f"/studies/{study_id}/trials/{trial_id}/mask.png")
    assert cv2.imdecode(np.frombuffer(mask.data, np.uint8), cv2.IMREAD_UNCHANGED).dtype == np.uint16
    assert admin_client.get(f"/studies/{study_id + 1}/trials/{trial_id}/overlay.png").status_code == 404
    assert admin_client.get(f"/studies/{study_id}/participants/{first_id}?page=9").status_code == 404
    for name, mimetype in (("trials.csv", "text/csv"), ("clicks.csv", "text/csv"), ("events.csv", "text/csv"), ("study.json", "application/json"), ("masks.zip", "application/zip")):
        with admin_client.get(f"/studies/{study_id}/export/{name}") as response:
            assert response.status_code == 200 and response.mimetype == mimetype, name
            assert f"study{study_id}-{name}" in response.headers["Content-Disposition"]
            data = response.get_data()
        if name == "masks.zip":
            assert "manifest.csv" in zipfile.ZipFile(io.BytesIO(data)).namelist()
    assert admin_client.get(f"/studies/{study_id}/export/secrets.txt").status_code == 404


def test_cli_precomputes_superpixels_and_exports(ctx, runner, tmp_path):
    study = done_study(tmp_path)
    result = runner.invoke(args=["egonet", "study-superpixels", str(study.id)])
    # Both activities were imported from the same images: the cache is keyed by content, so 2 computations do.
    assert result.exit_code == 0 and "2 frames computed, 2 already cached" in result.output, result.output
    result = runner.invoke(args=["egonet", "study-superpixels", str(study.id)])
    assert "0 frames computed, 4 already cached" in result.output
    out = tmp_path / "out"
    result = runner.invoke(args=["egonet", "study-export", str(study.id), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert (out / "study.json").exists() and (out / "clicks.csv").exists() and len(list((out / "masks" / "P01").glob("*.png"))) == 4
    result = runner.invoke(args=["egonet", "study-export", "999", "--out", str(out)])
    assert result.exit_code == 1 and "no study with id 999" in result.output and "Traceback" not in result.output
    (tmp_path / "file").write_text("x")
    result = runner.invoke(args=["egonet", "study-export", str(study.id), "--out", str(tmp_path / "file")])
    assert result.exit_code != 0 and "Traceback" not in result.output
