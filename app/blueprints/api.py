"""Read-only JSON views of the dataset (the labelling and study APIs build on
these), and a fresh CSRF token for pages whose token went stale."""

from flask import Blueprint, jsonify
from flask_wtf.csrf import generate_csrf

from app.blueprints.frames import media_urls
from app.extensions import db
from app.models import Activity, Frame, Sequence
from app.security import public
from app.services import frames as frames_service

bp = Blueprint("api", __name__, url_prefix="/api")


def frame_json(frame: Frame, status) -> dict:
    return {
        "id": frame.id,
        "activity": frame.sequence.activity.name,
        "sequence": frame.sequence.name,
        "index": frame.index,
        "timestamp_s": frame.timestamp_s,
        "source_name": frame.source_name,
        "width": frame.width,
        "height": frame.height,
        "content_hash": frame.content_hash,
        "intrinsics": frame.intrinsics,
        "status": status.value,
        **media_urls(frame),
        "meta": frames_service.shown_meta(frame),  # without the demo renderer's truth
    }


@bp.get("/activities")
def activities():
    return {
        "activities": [
            {"id": s.activity.id, "name": s.activity.name, "frames": s.frames, "by_status": s.by_status}
            for s in frames_service.activity_summaries()
        ]
    }


@bp.get("/activities/<int:activity_id>/frames")
def activity_frames(activity_id: int):
    act = db.get_or_404(Activity, activity_id)
    ids = db.session.execute(
        db.select(Frame).join(Sequence).where(Sequence.activity_id == act.id).order_by(Sequence.name, Frame.index)
    ).scalars().all()
    statuses = frames_service.frame_statuses([f.id for f in ids])
    return {"activity": act.name, "frames": [frame_json(f, statuses[f.id]) for f in ids]}


@bp.get("/frames/<int:frame_id>")
def frame(frame_id: int):
    fr = db.get_or_404(Frame, frame_id)
    return frame_json(fr, frames_service.frame_statuses([fr.id])[fr.id])


@bp.get("/csrf-token")
@public
def csrf_token():
    """The session's CSRF token (made if it has none). A page asks for it when a
    save was refused for its token: the session changed while the page was open
    (signed out and in again in another tab, or the server's key changed)."""
    response = jsonify(csrf_token=generate_csrf())
    response.headers["Cache-Control"] = "no-store"
    return response
