"""Human-study builder and results (admin pages).

List and create studies, add participants (codes or single-use links),
follow their progress, look at each participant's soft masks and the mean
map per frame over the frame (the paper's Fig. 5), and export the results.
"""

import json

from flask import Blueprint, Response, flash, redirect, render_template, request, stream_with_context, url_for
from flask_login import current_user
from app.forms import Form
from wtforms import (
    BooleanField,
    FloatField,
    IntegerField,
    SelectChoice,
    SelectField,
    SelectMultipleField,
    StringField,
    TextAreaField,
)
from wtforms.validators import DataRequired, InputRequired, Length, NumberRange, Optional
from wtforms.widgets import CheckboxInput, ListWidget

from app.errors import Problem
from app.extensions import db
from app.models import Role
from app.models.studies import ANSWERED, EntryKind, Participant, Study, StudyFrame, Trial
from app.security import roles
from app.services import ground_truth
from app.services import studies
from egonet.clicks import SUPERPIXEL_DEFAULTS

bp = Blueprint("studies", __name__, url_prefix="/studies")

PER_PAGE = 60
# Service field names -> form field names, where they differ.
FORM_FIELDS = {"time_limit_s": "time_limit_min"}


class StudyForm(Form):
    name = StringField("Name", validators=[DataRequired(), Length(max=200)])
    activities = SelectMultipleField(
        "Activities",
        coerce=int,
        widget=ListWidget(prefix_label=False),
        option_widget=CheckboxInput(),
        validators=[DataRequired(message="Choose at least one activity.")],
    )
    frames_per_activity = IntegerField("Frames per activity", default=100, validators=[InputRequired(), NumberRange(1, 100_000)])
    seed = IntegerField("Seed", validators=[InputRequired(), NumberRange(0, 2**31 - 1)])
    time_limit_min = FloatField("Session time limit (minutes)", default=60, validators=[InputRequired(), NumberRange(0.05, 7 * 24 * 60)])
    trial_limit_s = IntegerField("Per-trial limit (seconds, empty for none)", validators=[Optional(), NumberRange(1, 24 * 3600)])
    multiple_clicks = BooleanField("Several clicks per frame (then Next; otherwise one click answers)", default=True)
    sigma_px = FloatField("Click width sigma (native pixels)", default=60.0, validators=[InputRequired(), NumberRange(0.5, 10_000)])
    superpixel_method = SelectField("Superpixels", choices=[SelectChoice("hierarchical", "Hierarchical (boundaries, like MCG)"),
                                                             SelectChoice("slic", "SLIC"), SelectChoice("felzenszwalb", "Felzenszwalb")],
                                    default=SUPERPIXEL_DEFAULTS.method)
    fine_regions = IntegerField("Hierarchy: fine regions", default=SUPERPIXEL_DEFAULTS.fine_regions, validators=[Optional()])
    level = FloatField("Hierarchy: merge level", default=SUPERPIXEL_DEFAULTS.level, validators=[Optional()])
    n_segments = IntegerField("SLIC regions", default=SUPERPIXEL_DEFAULTS.n_segments, validators=[Optional()])
    compactness = FloatField("SLIC compactness", default=SUPERPIXEL_DEFAULTS.compactness, validators=[Optional()])
    scale = FloatField("Felzenszwalb scale", default=SUPERPIXEL_DEFAULTS.scale, validators=[Optional()])
    min_size = IntegerField("Felzenszwalb minimum region size", default=SUPERPIXEL_DEFAULTS.min_size, validators=[Optional()])
    max_side = IntegerField("Working resolution: longest side (px, empty for native)", default=SUPERPIXEL_DEFAULTS.max_side,
                            validators=[Optional()])
    instructions = TextAreaField("Instructions", default=studies.DEFAULT_INSTRUCTIONS, validators=[Length(max=20_000)])
    consent = TextAreaField("Consent", default=studies.DEFAULT_CONSENT, validators=[Length(max=20_000)])


class ParticipantsForm(Form):
    count = IntegerField("How many", default=5, validators=[InputRequired(), NumberRange(1, 500)])
    entry = SelectField("Entry", choices=[SelectChoice("code", "access codes"), SelectChoice("link", "single-use links (and codes)")], default="code")


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
    page = request.args.get("page", 1, type=int)
    if page < 1:
        raise Problem("page must be a positive integer", fields={"page": "must be >= 1"})
    return page


def _png(data: bytes) -> Response:
    # Results change while participants answer: never cached.
    return Response(data, mimetype="image/png", headers={"Cache-Control": "no-store"})


@bp.get("/")
@roles(Role.ADMIN)
def index():
    return render_template("studies/index.html", rows=studies.study_summaries())


@bp.route("/new", methods=["GET", "POST"])
@roles(Role.ADMIN)
def create():
    counts = studies.eligible_counts()
    form = StudyForm()
    form.activities.choices = [SelectChoice(activity.id, activity.name) for activity, _ in counts]
    if request.method == "GET":
        form.seed.data = studies.new_seed()
    if form.validate_on_submit():
        method = form.superpixel_method.data
        options = {name: getattr(form, name).data for name in studies.SUPERPIXEL_OPTIONS[method]}
        try:
            study = studies.create_study(
                name=form.name.data,
                activity_ids=form.activities.data,
                frames_per_activity=form.frames_per_activity.data,
                seed=form.seed.data,
                time_limit_s=max(1, round(form.time_limit_min.data * 60)),
                trial_limit_s=form.trial_limit_s.data,
                multiple_clicks=form.multiple_clicks.data,
                sigma_px=form.sigma_px.data,
                superpixels={"method": method, **options, "max_side": form.max_side.data},
                instructions=form.instructions.data or "",
                consent=form.consent.data or "",
                created_by=current_user._get_current_object(),
            )
        except studies.StudyProblem as exc:
            target = getattr(form, FORM_FIELDS.get(exc.field, exc.field or ""), None)
            if target is not None:
                target.errors = [*target.errors, str(exc)]
            else:
                flash(str(exc), "error")
        else:
            flash(f"Study created: {len(study.frames)} frames drawn with seed {study.seed}.")
            return redirect(url_for("studies.detail", study_id=study.id))
    status = 400 if request.method == "POST" else 200
    return render_template("studies/new.html", form=form, counts=counts), status


def _detail(study: Study, form: ParticipantsForm, status: int = 200):
    activities, cached = studies.activity_table(study)
    return render_template(
        "studies/detail.html",
        study=study,
        activities=activities,
        cached=cached,
        progress=[studies.progress(p) for p in study.participants],
        form=form,
        exports=studies.EXPORTS,
        format_code=studies.format_code,
        grace=studies.LATE_GRACE_S,
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
            created = studies.add_participants(study, count=form.count.data, entry=EntryKind(form.entry.data))
        except studies.StudyProblem as exc:
            form.count.errors = [*form.count.errors, str(exc)]
        else:
            flash(f"{len(created)} participants added.")
            return redirect(url_for("studies.detail", study_id=study.id) + "#participants")
    return _detail(study, form, 400)


@bp.get("/<int:study_id>/participants/<int:participant_id>")
@roles(Role.ADMIN)
def participant(study_id: int, participant_id: int):
    study = _study(study_id)
    person = db.session.get(Participant, participant_id)
    if person is None or person.study_id != study.id:
        raise Problem("no such participant in this study", status=404)
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
    return render_template("studies/frames.html", study=study, frames=shown, answered=answered, page=page, pages=pages)


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
    width = request.args.get("width", 640, type=int)
    return _png(studies.overlay_png(study_frame.frame, mean, outline=outline, max_width=min(max(width, 64), 2048)))


@bp.get("/<int:study_id>/trials/<int:trial_id>/overlay.png")
@roles(Role.ADMIN)
def trial_overlay(study_id: int, trial_id: int):
    """One participant's soft mask over the frame, with their clicks."""
    trial = _study_trial(study_id, trial_id)
    mask = studies.trial_soft_mask(trial) if trial.outcome in ANSWERED else None
    width = request.args.get("width", 640, type=int)
    points = [(c.x, c.y) for c in trial.clicks]
    return _png(studies.overlay_png(trial.frame, mask, points=points, max_width=min(max(width, 64), 2048)))


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
    """The study's results: trials, clicks and events as CSV, everything as JSON, soft masks as PNGs in a zip."""
    study = _study(study_id)
    if export_name not in studies.EXPORTS:
        raise Problem(f"unknown export {export_name!r}; choose one of {', '.join(studies.EXPORTS)}", status=404)
    headers = {"Content-Disposition": f'attachment; filename="study{study.id}-{export_name}"'}
    if export_name.endswith(".csv"):
        table = export_name.removesuffix(".csv")
        return Response(studies.export_csv(study, table), mimetype="text/csv", headers=headers)
    if export_name == "study.json":
        return Response(json.dumps(studies.export_json(study), indent=1), mimetype="application/json", headers=headers)

    def stream():
        # The zip is written while it is sent, after this view's database
        # session has closed: load the study again in the streaming context.
        yield from studies.masks_zip(db.session.get(Study, study_id))

    return Response(stream_with_context(stream()), mimetype="application/zip", headers=headers)
