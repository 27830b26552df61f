"""Pages for browsing the dataset: activities, frame grids, the frame viewer, media."""

from flask import Blueprint, abort, current_app, flash, redirect, render_template, send_file, url_for

from app.errors import Problem
from app.extensions import db
from app.forms import PointsFileForm
from app.models import Activity, Frame, Role
from app.models.training import Checkpoint, Prediction
from app.services import activations, attention_points, labelling, media
from app.services import frames as frames_service
from app.services import training as training_service
from app.security import roles
from app.validation import query_int

bp = Blueprint("frames", __name__)


def media_urls(frame: Frame) -> dict[str, str | None]:
    """Where a page loads the frame's RGB, depth and DHG images (None: the frame has none)."""
    return {
        "rgb_url": url_for("frames.media_file", name=frame.rgb_path),
        "depth_url": url_for("frames.depth", frame_id=frame.id) if frame.depth_path else None,
        "dhg_url": url_for("frames.media_file", name=frame.dhg_path) if frame.dhg_path else None,
    }


@bp.get("/")
def index():
    return render_template("frames/index.html", summaries=frames_service.activity_summaries())


@bp.get("/activities/<int:activity_id>")
def activity(activity_id: int):
    act = db.get_or_404(Activity, activity_id)
    page = query_int("page") or 1
    frames, pages = frames_service.frame_page(act, page, current_app.config["FRAMES_PER_PAGE"])
    if page > pages:
        abort(404, f"page {page} does not exist (the activity has {pages})")
    statuses = frames_service.frame_statuses([f.id for f in frames])
    return render_template(
        "frames/activity.html",
        activity=act,
        summary=frames_service.activity_summary(act),
        frames=frames,
        statuses=statuses,
        page=page,
        pages=pages,
        points_form=PointsFileForm(formdata=None),
    )


@bp.post("/activities/<int:activity_id>/points")
@roles(Role.ADMIN)
def import_points(activity_id: int):
    """Ground truth from attention points for the activity's frames (``flask egonet import-points`` from the page)."""
    act = db.get_or_404(Activity, activity_id)
    form = PointsFileForm()
    if not form.validate_on_submit():
        raise Problem("choose a CSV file of points (frame,x,y), and a sigma from 0.5 to 10,000 px or none",
                      fields={name: "; ".join(errors) for name, errors in form.errors.items()})
    flash(attention_points.import_upload(form.points.data, activity=act.name, sigma=form.sigma.data).summary())
    return redirect(url_for("frames.activity", activity_id=act.id))


@bp.get("/frames/<int:frame_id>")
def frame(frame_id: int):
    fr = db.get_or_404(Frame, frame_id)
    previous, following = frames_service.neighbours(fr)
    status = frames_service.frame_statuses([fr.id])[fr.id]
    prediction = training_service.latest_prediction(fr.id)
    spread = frames_service.prediction_range(prediction) if prediction else None
    chosen = query_int("checkpoint")
    figure = None
    if chosen is not None:
        checkpoint = db.get_or_404(Checkpoint, chosen)
        figure = {"checkpoint": checkpoint, "message": activations.page_message(checkpoint, fr)}
    return render_template(
        "frames/frame.html",
        frame=fr,
        status=status,
        previous=previous,
        following=following,
        prediction=prediction,
        spread=spread,
        meta=frames_service.shown_meta(fr),
        viewer_config=viewer_config(fr, prediction, spread),
        checkpoints=activations.checkpoint_choices(),
        figure=figure,
    )


def viewer_config(frame: Frame, prediction: Prediction | None, spread) -> dict:
    """What the viewer's script draws: every annotation's instances (colour, kind, mask URL) and the heat map's scales."""
    annotations, colour = [], 0
    listed = frames_service.viewer_annotations(frame)
    sources = attention_points.sources_of(a for a, _ in listed)
    for annotation, shown in listed:
        instances = []
        for instance in annotation.instances:
            instances.append({
                "position": instance.position,
                "kind": instance.kind.value if instance.kind else None,
                "label": instance.label,
                "colour": labelling.instance_colour(colour),
                "mask_url": url_for("label.instance_mask", annotation_id=annotation.id, position=instance.position),
            })
            colour += 1
        points = sources.get(annotation.id)
        annotations.append({"id": annotation.id, "author": annotation.author.username, "status": annotation.status.value,
                            "no_action_object": annotation.no_action_object, "shown": shown, "instances": instances,
                            "source": attention_points.describe(points) if points else None,
                            "points": points.points if points else []})
    config = {"frame": {"width": frame.width, "height": frame.height}, "annotations": annotations, "prediction": None}
    if prediction is not None:
        config["prediction"] = {
            "overlay_url": url_for("training.prediction_overlay", prediction_id=prediction.id),
            "normalised_url": url_for("frames.normalised_prediction", prediction_id=prediction.id)
            if spread.can_normalise else None,
            "low": spread.low,
            "high": spread.high,
        }
    return config


@bp.get("/frames/predictions/<int:prediction_id>/normalised.png")
def normalised_prediction(prediction_id: int):
    """The prediction's heat map stretched to its own range: for the eye only (the viewer's switch)."""
    prediction = db.get_or_404(Prediction, prediction_id)
    return send_file(frames_service.normalised_overlay(prediction), mimetype="image/png")


@bp.get("/frames/<int:frame_id>/activations/<int:checkpoint_id>.png")
def activations_figure(frame_id: int, checkpoint_id: int):
    """The paper's Figure 3 for this checkpoint on this frame (drawn on first use for small models, then cached)."""
    fr = db.get_or_404(Frame, frame_id)
    checkpoint = db.get_or_404(Checkpoint, checkpoint_id)
    return send_file(activations.figure_path(checkpoint, fr, in_request=True), mimetype="image/png", max_age=3600)


@bp.get("/frames/colour-bar.png")
def colour_bar():
    return send_file(frames_service.colour_bar(), mimetype="image/png", max_age=86400)


@bp.get("/frames/<int:frame_id>/thumb.jpg")
def thumbnail(frame_id: int):
    fr = db.get_or_404(Frame, frame_id)
    return send_file(frames_service.thumbnail(fr), mimetype="image/jpeg", max_age=86400)


@bp.get("/frames/<int:frame_id>/depth.png")
def depth(frame_id: int):
    fr = db.get_or_404(Frame, frame_id)
    if fr.depth_path is None:
        abort(404, "this frame has no depth map")
    return send_file(frames_service.depth_preview(fr), mimetype="image/png", max_age=86400)


@bp.get("/frames/<int:frame_id>/points.bin")
def points(frame_id: int):
    """The frame's 3-D points for the viewer (``egonet.pointcloud.encode_points``); ``?max=`` bounds them."""
    from app.services import pointcloud

    fr = db.get_or_404(Frame, frame_id)
    max_points = query_int("max") or pointcloud.BROWSER_POINTS
    data = pointcloud.browser_points(fr, max_points=max_points, prediction_id=query_int("prediction"))
    return current_app.response_class(data, mimetype="application/octet-stream")


@bp.get("/media/<path:name>")
def media_file(name: str):
    # Content-addressed: a name never changes meaning, so it can be cached forever
    # (by the signed-in browser only: app.security marks it private).
    try:
        path = media.local_path(name) if media.NAME.fullmatch(name) else None
    except FileNotFoundError:
        path = None
    if path is None or not path.is_file():
        abort(404)
    return send_file(path, max_age=365 * 86400)
