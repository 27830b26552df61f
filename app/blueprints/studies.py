"""Human-study builder and results (admin pages).

List, create (from the builder's form or a definition file), edit before
anyone entered, duplicate, delete, open, pause and close studies; add
participants (codes in bulk or single-use links, or pilots), deactivate them
or delete their data when they withdraw, follow their progress and checks,
clear an address's entry count (ending its waits); look at each participant's soft masks and the
mean map per frame over the frame (the paper's Fig. 5), and export the
results, the participants (codes, status, completion codes) and the
study's definition file.
"""

import json

from flask import Blueprint, Response, current_app, flash, redirect, render_template, request, stream_with_context, url_for
from flask_login import current_user
from wtforms import SelectChoice

from app.errors import Problem
from app.extensions import db
from app.forms import DefinitionFileForm, ParticipantsForm, StudyForm
from app.models import Activity, Role
from app.models.studies import ANSWERED, EntryKind, FrameKind, Participant, Study, StudyFrame, Trial
from app.security import roles
from app.services import ground_truth, studies
from app.services.scoring.cache import forget_participant
from app.throttle import clear_entry_lock, entry_locks, locked_s
from app.validation import query_int
from egonet.io import UNSAFE_REASON, UnsafeText, decode_json

bp = Blueprint("studies", __name__, url_prefix="/studies")

PER_PAGE = 60
MAX_DEFINITION_BYTES = 1024 * 1024


def _study(study_id: int) -> Study:
    return db.get_or_404(Study, study_id)


def _study_trial(study_id: int, trial_id: int) -> Trial:
    """A trial of this study (404 for a trial of another study)."""
    trial = db.session.get(Trial, trial_id)
    if trial is None or trial.participant.study_id != study_id:
        raise Problem("no such trial in this study", status=404)
    return trial


def _study_frame(study_id: int, study_frame_id: int) -> StudyFrame:
    study_frame = db.session.get(StudyFrame, study_frame_id)
    if study_frame is None or study_frame.study_id != study_id:
        raise Problem("no such frame in this study", status=404)
    return study_frame


def _page() -> int:
    return query_int("page") or 1


def _width() -> int:
    """An overlay's ``?width=`` (CSS px), kept within 64-2048."""
    return min(max(query_int("width", min=0) or 640, 64), 2048)


def _png(data: bytes) -> Response:
    # Results change while participants answer: never cached.
    return Response(data, mimetype="image/png", headers={"Cache-Control": "no-store"})


@bp.get("/")
@roles(Role.ADMIN)
def index():
    return render_template("studies/index.html", rows=studies.study_summaries())


def _builder(form: StudyForm, *, study: Study | None = None, status: int = 200):
    return render_template(
        "studies/new.html", form=form, counts=studies.eligible_counts(), study=study, widths=_eligible_widths(),
        upload=DefinitionFileForm(formdata=None), reference=studies.REFERENCE_WIDTH,
    ), status  # fmt: skip


def _eligible_widths() -> list[tuple[int, float]]:
    """The widths of the eligible frames with the click width scaled to each (the builder's default)."""
    widths = sorted({frame.width for frame in ground_truth.labelled_frames()})
    return [(w, studies.scaled_sigma(w)) for w in widths]


def _activity_choices(form: StudyForm) -> tuple[dict[int, str], dict[str, int]]:
    activities = db.session.execute(db.select(Activity).order_by(Activity.name)).scalars().all()
    form.activities.choices = [SelectChoice(a.id, a.name) for a in activities]
    return {a.id: a.name for a in activities}, {a.name: a.id for a in activities}


def _show_problem(form: StudyForm, exc: studies.StudyProblem) -> None:
    target = form.field_for(exc.field)
    if target is not None:
        target.errors = [*target.errors, str(exc)]
    else:
        flash(str(exc), "error")


@bp.route("/new", methods=["GET", "POST"])
@roles(Role.ADMIN)
def create():
    form = StudyForm()
    names, _ = _activity_choices(form)
    if request.method == "GET":
        form.seed.data = studies.new_seed()
    if form.validate_on_submit():
        doc = form.definition(names)
        if doc is not None:
            try:
                study = studies.study_from_definition(doc, created_by=current_user._get_current_object())
            except studies.StudyProblem as exc:
                _show_problem(form, exc)
            else:
                flash(f"Study created: {len(study.frames_of(FrameKind.MAIN))} frames drawn with seed {study.seed}.")
                return redirect(url_for("studies.detail", study_id=study.id))
    return _builder(form, status=400 if request.method == "POST" else 200)


@bp.post("/import")
@roles(Role.ADMIN)
def create_from_file():
    """Create a study from an uploaded definition file (the one a study's definition.json download gives)."""
    upload = DefinitionFileForm()
    if not upload.validate_on_submit():
        raise Problem("choose a definition file (JSON)", fields={"definition": "required"})
    data = upload.definition.data.read(MAX_DEFINITION_BYTES + 1)
    if len(data) > MAX_DEFINITION_BYTES:
        raise Problem("a definition file has at most 1 MiB", status=413, fields={"definition": "too large"})
    try:
        doc = decode_json(data)
    except UnsafeText as exc:
        raise Problem(f"the definition file's {exc.field} {UNSAFE_REASON}", fields={"definition": UNSAFE_REASON}) from None
    except ValueError as exc:
        raise Problem(f"the definition file is not valid JSON: {exc}", fields={"definition": "not valid JSON"}) from None
    study = studies.study_from_definition(doc, created_by=current_user._get_current_object())
    flash(f"Study created from the definition file: {len(study.frames_of(FrameKind.MAIN))} frames drawn with seed {study.seed}.")
    return redirect(url_for("studies.detail", study_id=study.id))


@bp.route("/<int:study_id>/edit", methods=["GET", "POST"])
@roles(Role.ADMIN)
def edit(study_id: int):
    """Change a study's settings (its frames are drawn again) until its first participant enters."""
    study = _study(study_id)
    if studies.entered(study):
        flash("Participants have entered this study: it can no longer be edited. Duplicate it to run it again with changes.", "error")
        return redirect(url_for("studies.detail", study_id=study.id))
    form = StudyForm(formdata=None) if request.method == "GET" else StudyForm()
    names, ids = _activity_choices(form)
    if request.method == "GET":
        form.fill(studies.definition_of(study), ids)
        form.version.data = str(study.version)
    elif form.validate_on_submit():
        doc = form.definition(names)
        text = form.version.data or ""
        version = int(text) if text.isascii() and text.isdigit() and len(text) <= 9 else -1
        if doc is not None:
            try:
                studies.update_from_definition(study, doc, version=version)
            except studies.StudyProblem as exc:
                _show_problem(form, exc)
            else:
                flash("Study saved: its frames were drawn again.")
                return redirect(url_for("studies.detail", study_id=study_id))
    return _builder(form, study=study, status=400 if request.method == "POST" else 200)


@bp.post("/<int:study_id>/duplicate")
@roles(Role.ADMIN)
def duplicate(study_id: int):
    copy = studies.duplicate_study(_study(study_id), created_by=current_user._get_current_object())
    flash(f"Duplicated: the same frames and settings, no participants yet (study {copy.id}).")
    return redirect(url_for("studies.detail", study_id=copy.id))


@bp.post("/<int:study_id>/delete")
@roles(Role.ADMIN)
def delete(study_id: int):
    study = _study(study_id)
    name = study.name
    studies.delete_study(study)
    flash(f"Study {name!r} deleted.")
    return redirect(url_for("studies.index"))


@bp.post("/<int:study_id>/status")
@roles(Role.ADMIN)
def set_status(study_id: int):
    """Open, pause or close the study (new participants only; those already in finish)."""
    study = studies.set_status(_study(study_id), request.form.get("status", ""))
    flash(f"The study is {study.status.value}.")
    return redirect(url_for("studies.detail", study_id=study.id))


def _detail(study: Study, form: ParticipantsForm, status: int = 200):
    studies.close_overdue([p.id for p in study.participants])
    activities, cached = studies.activity_table(study)
    people = list(study.participants)
    open_link = url_for("study.open_link", open_token=study.open_link_token, _external=True) if study.open_link_token else None
    return render_template(
        "studies/detail.html",
        study=study,
        activities=activities,
        cached=cached,
        progress=[studies.progress(p) for p in people],
        checks=studies.checks_of(people),
        conditions=studies.condition_table(study),
        places=studies.places_taken(study),
        entered=studies.entered(study),
        open_link=open_link,
        platform=studies.platform_urls(open_link) if open_link else None,
        practice=study.frames_of(FrameKind.PRACTICE),
        catch=study.frames_of(FrameKind.CATCH),
        main=study.frames_of(FrameKind.MAIN),
        form=form,
        exports=studies.EXPORTS,
        format_code=studies.format_code,
        grace=studies.LATE_GRACE_S,
        locks=[(row, locked_s(row)) for row in entry_locks(study.id)],
        lock_budget=current_app.config["RATELIMIT_ENTRY_FAILURES"],
        open_budget=current_app.config["RATELIMIT_OPEN_ADMISSIONS"],
    ), status


@bp.get("/<int:study_id>")
@roles(Role.ADMIN)
def detail(study_id: int):
    return _detail(_study(study_id), ParticipantsForm(formdata=None))


@bp.post("/<int:study_id>/participants")
@roles(Role.ADMIN)
def add_participants(study_id: int):
    study = _study(study_id)
    form = ParticipantsForm()
    if form.validate_on_submit():
        try:
            created = studies.add_participants(
                study, count=form.count.data, entry=EntryKind(form.entry.data), pilot=form.pilot.data
            )
        except studies.StudyProblem as exc:
            form.count.errors = [*form.count.errors, str(exc)]
        else:
            kind = "pilot" if form.pilot.data else "participant"
            flash(f"{len(created)} {kind}{'s' if len(created) != 1 else ''} added: download their codes as participants.csv.")
            return redirect(url_for("studies.detail", study_id=study.id) + "#participants")
    return _detail(study, form, 400)


def _person(study: Study, participant_id: int) -> Participant:
    person = db.session.get(Participant, participant_id)
    if person is None or person.study_id != study.id:
        raise Problem("no such participant in this study", status=404)
    return person


@bp.post("/<int:study_id>/participants/<int:participant_id>/active")
@roles(Role.ADMIN)
def set_active(study_id: int, participant_id: int):
    """Deactivate a participant (their code and session stop working, their place is freed), or activate them again."""
    study = _study(study_id)
    person = _person(study, participant_id)
    value = request.form.get("active")
    if value not in ("0", "1"):
        raise Problem("active must be 0 or 1", fields={"active": "must be 0 or 1"})
    studies.set_active(person, value == "1")
    flash(f"{person.label} {'activated' if value == '1' else 'deactivated'}.")
    return redirect(url_for("studies.detail", study_id=study.id) + "#participants")


@bp.post("/<int:study_id>/participants/<int:participant_id>/release")
@roles(Role.ADMIN)
def release(study_id: int, participant_id: int):
    """Let an open-link participant who lost their first browser continue in a new one (``studies.release``)."""
    study = _study(study_id)
    person = _person(study, participant_id)
    studies.release(person)
    flash(f"{person.label} can continue in a new browser: they open the study's link again.")
    return redirect(url_for("studies.detail", study_id=study.id) + "#participants")
@bp.post("/<int:study_id>/entry-locks/<int:lock_id>/clear")
@roles(Role.ADMIN)
def clear_lock(study_id: int, lock_id: int):
    """Forget the entries counted for one address (codes and links, or this study's open link), ending its waits."""
    row = clear_entry_lock(_study(study_id).id, lock_id)
    flash(f"Entries counted from {row.address} forgotten: it need not wait.")
    return redirect(url_for("studies.detail", study_id=study_id) + "#entry-locks")


@bp.post("/<int:study_id>/participants/<int:participant_id>/withdraw")
@roles(Role.ADMIN)
def withdraw(study_id: int, participant_id: int):
    """Delete a participant's data on their request; ``confirm`` must repeat their label (``P03``)."""
    study = _study(study_id)
    person = _person(study, participant_id)
    if request.form.get("confirm", "").strip().upper() != person.label:
        raise Problem(f"type {person.label} to confirm the withdrawal", fields={"confirm": f"must be {person.label}"})
    deleted = studies.withdraw(person, by=current_user._get_current_object())
    forget_participant(person.id)
    flash(f"{person.label} withdrawn: {deleted} trial{'s' if deleted != 1 else ''} and their clicks, events and maps deleted.")
    return redirect(url_for("studies.participant", study_id=study.id, participant_id=person.id))


@bp.get("/<int:study_id>/participants/<int:participant_id>")
@roles(Role.ADMIN)
def participant(study_id: int, participant_id: int):
    study = _study(study_id)
    person = _person(study, participant_id)
    studies.close_overdue([person.id])
    page = _page()
    total = len(person.trials)
    pages = max(1, -(-total // PER_PAGE))
    if page > pages:
        raise Problem(f"page {page} does not exist (there are {pages})", status=404)
    trials = person.trials[(page - 1) * PER_PAGE : page * PER_PAGE]
    return render_template(
        "studies/participant.html",
        study=study,
        person=person,
        progress=studies.progress(person),
        checks=studies.checks_of([person])[person.id],
        trials=trials,
        answered=ANSWERED,
        page=page,
        pages=pages,
    )


@bp.get("/<int:study_id>/frames")
@roles(Role.ADMIN)
def frames(study_id: int):
    study = _study(study_id)
    page = _page()
    pages = max(1, -(-len(study.frames) // PER_PAGE))
    if page > pages:
        raise Problem(f"page {page} does not exist (there are {pages})", status=404)
    shown = study.frames[(page - 1) * PER_PAGE : page * PER_PAGE]
    answered = studies.answered_counts(shown)
    return render_template("studies/frames.html", study=study, frames=shown, answered=answered, page=page, pages=pages,
                           cap=studies.cap_summary(study))


@bp.get("/<int:study_id>/frames/<int:study_frame_id>")
@roles(Role.ADMIN)
def frame(study_id: int, study_frame_id: int):
    study = _study(study_id)
    study_frame = _study_frame(study.id, study_frame_id)
    trials = studies.answered_trials(study_frame)
    return render_template("studies/frame.html", study=study, study_frame=study_frame, trials=trials)


@bp.get("/<int:study_id>/frames/<int:study_frame_id>/mean.png")
@roles(Role.ADMIN)
def mean_overlay(study_id: int, study_frame_id: int):
    """The mean soft mask over the frame; ``?outline=1`` adds the ground truth's outline."""
    study_frame = _study_frame(study_id, study_frame_id)
    mean, _ = studies.mean_soft_mask(study_frame)
    outline = None
    if request.args.get("outline") == "1":
        truth = ground_truth.ground_truths([study_frame.frame_id]).get(study_frame.frame_id)
        outline = ground_truth.mask_of(truth) if truth is not None else None
    return _png(studies.overlay_png(study_frame.frame, mean, outline=outline, max_width=_width()))


@bp.get("/<int:study_id>/trials/<int:trial_id>/overlay.png")
@roles(Role.ADMIN)
def trial_overlay(study_id: int, trial_id: int):
    """One participant's soft mask over the frame, with their clicks."""
    trial = _study_trial(study_id, trial_id)
    mask = studies.trial_soft_mask(trial) if trial.outcome in ANSWERED else None
    points = [(c.x, c.y) for c in trial.clicks]
    return _png(studies.overlay_png(trial.frame, mask, points=points, max_width=_width()))


@bp.get("/<int:study_id>/trials/<int:trial_id>/mask.png")
@roles(Role.ADMIN)
def trial_mask(study_id: int, trial_id: int):
    """One participant's soft mask as a 16-bit PNG at the frame's native size."""
    trial = _study_trial(study_id, trial_id)
    if trial.outcome not in ANSWERED:
        raise Problem("this trial has no answer, so no soft mask", status=404)
    return _png(studies.mask_png(studies.trial_soft_mask(trial)))


@bp.get("/<int:study_id>/export/<export_name>")
@roles(Role.ADMIN)
def export(study_id: int, export_name: str):
    """The study's results: trials, clicks, events and participants as CSV, everything as JSON, the study's
    definition file, soft masks as PNGs in a zip."""
    study = _study(study_id)
    if export_name not in studies.EXPORTS:
        raise Problem(f"unknown export {export_name!r}; choose one of {', '.join(studies.EXPORTS)}", status=404)
    headers = {"Content-Disposition": f'attachment; filename="study{study.id}-{export_name}"'}
    if export_name.endswith(".csv"):
        table = export_name.removesuffix(".csv")
        return Response(studies.export_csv(study, table), mimetype="text/csv", headers=headers)
    if export_name == "study.json":
        return Response(json.dumps(studies.export_json(study), indent=1), mimetype="application/json", headers=headers)
    if export_name == "definition.json":
        return Response(json.dumps(studies.definition_of(study), indent=1), mimetype="application/json", headers=headers)

    def stream():
        # The zip is written while it is sent, after this view's database
        # session has closed: load the study again in the streaming context.
        yield from studies.masks_zip(db.session.get(Study, study_id))

    return Response(stream_with_context(stream()), mimetype="application/zip", headers=headers)
