"""Pages for browsing the dataset: activities, frame grids, the frame viewer, media."""

from flask import Blueprint, abort, current_app, render_template, request, send_file, send_from_directory

from app.extensions import db
from app.models import Activity, Frame
from app.services import frames as frames_service
from app.services import media
from app.services import training as training_service

bp = Blueprint("frames", __name__)


@bp.get("/")
def index():
    return render_template("frames/index.html", summaries=frames_service.activity_summaries())


@bp.get("/activities/<int:activity_id>")
def activity(activity_id: int):
    act = db.get_or_404(Activity, activity_id)
    page = request.args.get("page", 1, type=int)
    if page < 1:
        abort(400, "page must be a positive integer")
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
    )


@bp.get("/frames/<int:frame_id>")
def frame(frame_id: int):
    fr = db.get_or_404(Frame, frame_id)
    previous, following = frames_service.neighbours(fr)
    status = frames_service.frame_statuses([fr.id])[fr.id]
    prediction = training_service.latest_prediction(fr.id)
    return render_template(
        "frames/frame.html", frame=fr, status=status, previous=previous, following=following, prediction=prediction
    )


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
    max_points = request.args.get("max", pointcloud.BROWSER_POINTS, type=int)
    data = pointcloud.browser_points(fr, max_points=max_points, prediction_id=request.args.get("prediction", type=int))
    return current_app.response_class(data, mimetype="application/octet-stream")


@bp.get("/media/<path:name>")
def media_file(name: str):
    # Content-addressed: a name never changes meaning, so it can be cached forever
    # (by the signed-in browser only: app.security marks it private).
    return send_from_directory(media.media_root(), name, max_age=365 * 86400)
