"""Training runs: start through the queue, watch progress, list checkpoints.

Staff see runs, checkpoints and predictions, their charts and per-frame
results, and download checkpoints and configurations; only admins start,
cancel, resume, rename, tag and delete runs. A run never trains inside a
request: starting one records the row and queues the job for ``flask
egonet worker``. The pages poll ``status`` for live progress and
``history`` for the charts.
"""

from flask import (
    Blueprint,
    abort,
    flash,
    jsonify,
    redirect,
    render_template,
    request,
    send_file,
    url_for,
)
from flask_login import current_user
from wtforms import (
    BooleanField,
    FloatField,
    IntegerField,
    SelectChoice,
    SelectField,
    SelectMultipleField,
    StringField,
)
from wtforms.validators import InputRequired, Length, NumberRange, Optional
from wtforms.widgets import CheckboxInput, ListWidget

from app.errors import Problem
from app.extensions import db
from app.forms import Form
from app.models import Activity, Role
from app.models.training import Checkpoint, Prediction, TrainingRun
from app.queue import enqueue
from app.security import current_role, roles
from app.services import training
from app.validation import Int, Str, json_body, query_int, query_ints, takes_json

bp = Blueprint("training", __name__, url_prefix="/training")

MODEL_CHOICES = [
    SelectChoice("egonet-lite", "egonet-lite (fast on a CPU)"),
    SelectChoice("egonet", "egonet (the paper's network, 138 M parameters: use a GPU)"),
    SelectChoice("egonet-rgb", "egonet-rgb (ablation: RGB stream only)"),
    SelectChoice("egonet-dhg", "egonet-dhg (ablation: DHG stream only)"),
    SelectChoice("single-stream", "single-stream (ablation: early fusion)"),
    SelectChoice("no-coords", "no-coords (ablation: no coordinate maps)"),
    SelectChoice("no-embedding", "no-embedding (ablation: fc9 removed)"),
]


class RunForm(Form):
    name = StringField("Name (optional)", validators=[Optional(), Length(max=200)])
    model = SelectField("Model", choices=MODEL_CHOICES, default="egonet-lite")
    folds = SelectField(
        "Evaluation",
        choices=[SelectChoice("loao", "leave one activity out (one model per activity)"), SelectChoice("single", "single split (last 20% of each activity)"),
                 SelectChoice("all", "all frames, none held out (score it on other activities: Tables 3 and 4)")],
        default="loao",
    )
    epochs = IntegerField("Epochs", default=10, validators=[InputRequired(), NumberRange(1, training.MAX_EPOCHS)])
    device = SelectField("Device", choices=[SelectChoice(d, d) for d in ("auto", "cpu", "cuda")], default="auto")
    width = IntegerField("Training width", default=320, validators=[InputRequired(), NumberRange(8, 4096)])
    height = IntegerField("Training height", default=240, validators=[InputRequired(), NumberRange(8, 4096)])
    lr = FloatField("Learning rate (empty: the model's default)", validators=[Optional(), NumberRange(min=1e-9, max=100)])
    batch_size = IntegerField("Batch size", default=4, validators=[InputRequired(), NumberRange(1, 512)])
    seed = IntegerField("Seed", default=0, validators=[InputRequired(), NumberRange(0, 2**31 - 1)])
    pretrained = BooleanField("Start egonet-lite from ImageNet weights")
    activities = SelectMultipleField(
        "Activities (none ticked: all)", coerce=int, widget=ListWidget(prefix_label=False), option_widget=CheckboxInput()
    )


def _form() -> RunForm:
    form = RunForm()
    activities = db.session.execute(db.select(Activity).order_by(Activity.name)).scalars()
    form.activities.choices = [SelectChoice(a.id, a.name) for a in activities]
    return form


def _run(run_id: int) -> TrainingRun:
    return db.get_or_404(TrainingRun, run_id)


def run_json(run: TrainingRun) -> dict:
    """What the page's poller shows of a run."""
    return {
        "id": run.id,
        "status": run.status.value,
        "progress": run.progress,
        "loss": run.loss,
        "eta_s": run.eta_s,
        "message": run.message,
        "mean": run.metrics.get("mean", {}),
        "updated_at": run.updated_at.isoformat(),
    }


def _index(form: RunForm, status: int = 200):
    tag = request.args.get("tag", "").strip()[:40] or None
    runs = training.runs_tagged(tag)
    charted = training.runs_with_history(r.id for r in runs)
    try:
        compare = set(training.parse_run_ids(request.args.get("compare", "")))
    except training.TrainingProblem:
        compare = set()
    if not compare:  # by default the newest three runs that have a history
        compare = {r.id for r in runs if r.id in charted}
        compare = set(sorted(compare, reverse=True)[:3])
    return (
        render_template(
            "training/index.html",
            runs=runs,
            checkpoints=[c for c in training.checkpoints() if not tag or c.run_id in {r.id for r in runs}],
            form=form,
            can_start=current_role() is Role.ADMIN,
            tag=tag,
            tags=training.all_tags(),
            compare=compare,
            max_compared=training.MAX_COMPARED_RUNS,
        ),
        status,
    )


@bp.get("/")
def index():
    return _index(_form())


@bp.post("/runs")
@roles(Role.ADMIN)
def start():
    form = _form()
    if form.validate_on_submit():
        try:
            run = training.start_run(
                training.RunRequest(
                    model=form.model.data,
                    folds=form.folds.data,
                    epochs=form.epochs.data,
                    device=form.device.data,
                    width=form.width.data,
                    height=form.height.data,
                    lr=form.lr.data,
                    batch_size=form.batch_size.data,
                    seed=form.seed.data,
                    pretrained=form.pretrained.data,
                    activity_ids=tuple(form.activities.data) or None,
                    name=form.name.data,
                ),
                created_by=current_user._get_current_object(),
            )
        except training.TrainingProblem as exc:
            target = getattr(form, {"size": "width"}.get(exc.field, exc.field or ""), None)
            if target is not None:
                target.errors = [*target.errors, str(exc)]
            else:
                flash(str(exc), "error")
        else:
            flash(f"Run {run.id} queued: the worker (flask egonet worker) will train it.")
            return redirect(url_for("training.index"))
    return _index(form, 400)


@bp.get("/status")
def status():
    wanted = query_ints("ids")
    query = db.select(TrainingRun).where(TrainingRun.id.in_(wanted)) if wanted else db.select(TrainingRun)
    runs = db.session.execute(query.order_by(TrainingRun.id.desc()).limit(100)).scalars()
    return {"runs": [run_json(run) for run in runs]}


@bp.get("/runs/<int:run_id>")
def detail(run_id: int):
    return _detail(_run(run_id))


def _detail(run: TrainingRun, *, edit_form: "EditForm | None" = None, status: int = 200):
    if edit_form is None:
        edit_form = EditForm(formdata=None, data={"name": run.name, "tags": ", ".join(run.tags or []), "version": run.version})
    return (
        render_template(
            "training/detail.html",
            run=run,
            predictions=training.frame_predictions(run),
            can_start=current_role() is Role.ADMIN,
            edit_form=edit_form,
        ),
        status,
    )


@bp.post("/runs/<int:run_id>/cancel")
@roles(Role.ADMIN)
def cancel(run_id: int):
    run = training.cancel_run(_run(run_id))
    flash(f"Run {run.id} cancelled.")
    return redirect(url_for("training.detail", run_id=run.id))


@bp.post("/runs/<int:run_id>/resume")
@roles(Role.ADMIN)
def resume(run_id: int):
    run = training.resume_run(_run(run_id))
    flash(f"Run {run.id} queued again: finished folds are kept.")
    return redirect(url_for("training.detail", run_id=run.id))


# --------------------------------------------------------------------------- the authors' released weights
# The page sends a .caffemodel in chunks (each under MAX_CONTENT_LENGTH); the worker converts it.

UPLOAD = {"filename": Str(min_len=1, max_len=255), "size": Int(min=1)}
FINISH = {
    "name": Str(max_len=200, nullable=True, default=None),
    "width": Int(min=8, max=4096, default=641),
    "height": Int(min=8, max=4096, default=481),
}


@bp.post("/weights/uploads")
@roles(Role.ADMIN)
@takes_json()
def weights_upload_start():
    data = json_body(UPLOAD)
    return training.start_upload(filename=data["filename"], size=data["size"], user=current_user._get_current_object()), 201


@bp.put("/weights/uploads/<upload>")
@roles(Role.ADMIN)
def weights_upload_chunk(upload: str):
    offset = query_int("offset", min=0)
    if offset is None:
        raise training.TrainingProblem("give the chunk's offset (?offset=N)", field="offset")
    received = training.write_chunk(upload, offset=offset, stream=request.stream, length=request.content_length,
                                    user=current_user._get_current_object())
    return {"received": received}


@bp.post("/weights/uploads/<upload>/finish")
@roles(Role.ADMIN)
@takes_json()
def weights_upload_finish(upload: str):
    data = json_body(FINISH)
    run = training.finish_upload(upload, name=data["name"], size=(data["height"], data["width"]),
                                 user=current_user._get_current_object())
    message = f"Run {run.id}: {run.config['released']['title']}, queued: the worker (flask egonet worker) converts it."
    return {"run_id": run.id, "release": run.config["released"]["release"], "message": message}, 201


@bp.delete("/weights/uploads/<upload>")
@roles(Role.ADMIN)
def weights_upload_cancel(upload: str):
    training.cancel_upload(upload, user=current_user._get_current_object())
    return "", 204


@bp.get("/predictions/<int:prediction_id>.png")
def prediction_overlay(prediction_id: int):
    prediction = db.get_or_404(Prediction, prediction_id)
    # Predicting a frame again replaces the map behind this id: revalidated (ETag), not cached for long.
    return send_file(training.prediction_overlay(prediction), mimetype="image/png")


# --------------------------------------------------------------------------- inspecting and managing runs


class EditForm(Form):
    name = StringField("Name", validators=[InputRequired(), Length(max=200)])
    tags = StringField("Tags (comma-separated)", validators=[Optional(), Length(max=600)])
    version = IntegerField(validators=[InputRequired(), NumberRange(0, 2**31 - 1)])


@bp.get("/history")
def history():
    """Epoch rows of some runs for the charts (``?runs=3,5&after=<last id seen>``), bounded pages."""
    run_ids = training.parse_run_ids(request.args.get("runs", ""))
    return training.chart_data(run_ids, after=query_int("after", min=0) or 0)


@bp.get("/checkpoints/<int:checkpoint_id>/download")
def download_checkpoint(checkpoint_id: int):
    path, name = training.checkpoint_file(db.get_or_404(Checkpoint, checkpoint_id))
    # send_file streams the file from disk; conditional requests and ranges are answered too.
    return send_file(path, mimetype="application/octet-stream", as_attachment=True, download_name=name, max_age=0)


@bp.get("/runs/<int:run_id>/config.json")
def run_config(run_id: int):
    run = _run(run_id)
    response = jsonify(training.run_config(run))
    response.headers["Content-Disposition"] = f'attachment; filename="run-{run.id}-config.json"'
    return response


@bp.post("/runs/<int:run_id>/edit")
@roles(Role.ADMIN)
def edit(run_id: int):
    run = _run(run_id)
    form = EditForm()
    if not form.validate_on_submit():
        return _detail(run, edit_form=form, status=400)
    try:
        training.edit_run(run, name=form.name.data, tags=training.parse_tags(form.tags.data or ""), version=form.version.data)
    except training.TrainingProblem as exc:
        if exc.status != 409:
            getattr(form, exc.field, form.name).errors = [str(exc)]
            return _detail(run, edit_form=form, status=exc.status)
        flash(f"Not saved: {exc}. Yours was: {form.name.data!r}, tags {form.tags.data or 'none'}.", "error")
        return _detail(run, status=409)
    flash(f"Run {run.id} saved.")
    return redirect(url_for("training.detail", run_id=run.id))


@bp.get("/runs/<int:run_id>/frames")
def frames(run_id: int):
    """Held-out frames of a run, worst F first, with the prediction, the truth and the DHG side by side."""
    run = _run(run_id)
    fold = request.args.get("fold") or None
    if fold is not None and fold not in {c.fold for c in run.checkpoints}:
        raise training.TrainingProblem(f"run {run.id} has no fold {fold[:120]!r}", field="fold", status=404)
    page = training.frame_page(run, page=query_int("page", max=10**6) or 1, fold=fold)
    thresholds = {c.id: c.metrics.get("threshold") for c in run.checkpoints}
    return render_template("training/frames.html", run=run, page=page, thresholds=thresholds,
                           can_start=current_role() is Role.ADMIN)


@bp.post("/runs/<int:run_id>/frames/score")
@roles(Role.ADMIN)
def score_frames(run_id: int):
    run = _run(run_id)
    missing = training.unscored_count(run)
    if missing:
        enqueue("score_frames", run.id)
        flash(f"Scoring {missing} held-out frames in the worker (flask egonet worker); reload in a moment.")
    else:
        flash("Every held-out frame of this run has its scores.")
    return redirect(url_for("training.frames", run_id=run.id))


@bp.get("/predictions/<int:prediction_id>/<kind>.png")
def prediction_picture(prediction_id: int, kind: str):
    if kind not in ("prediction", "truth"):
        abort(404)
    return send_file(training.prediction_picture(db.get_or_404(Prediction, prediction_id), kind), mimetype="image/png")


@bp.route("/runs/<int:run_id>/delete", methods=["GET", "POST"])
@roles(Role.ADMIN)
def delete(run_id: int):
    """GET: what deleting the run removes, and the button; POST: delete it (refused while it is queued or running)."""
    run = _run(run_id)
    if request.method == "GET":
        plan = training.deletion_plan(run)
        return render_template("training/delete.html", plan=plan), 200 if plan.allowed else 409
    name = f"#{run.id} {run.name}"
    counts = training.delete_run(run)
    flash(f"Run {name} deleted with {counts['checkpoints']} checkpoints, {counts['predictions']} predictions "
          f"({counts['media_files']} files) and {counts['epochs']} epoch records.")
    return redirect(url_for("training.index"))
