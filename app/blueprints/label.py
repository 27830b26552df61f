"""Labelling pages and API: GrabCut-assisted action-object masks.

Who may do what:
    * annotators and admins label: the labelling page, their own annotation
      (read, save, reopen, mask upload), presence on a frame;
    * reviewers and admins review: the review page, accept / reject, and a
      fix of a done annotation's masks before deciding;
    * all staff run GrabCut, each in their own sessions (a reviewer's fix
      uses it too), and keep their undo history of what they may edit;
    * all staff see the overview (with the review queue's mask thumbnails),
      read any annotation and its masks, and export (app.blueprints.exports).

Masks never travel inside JSON as base64: the page saves them as COCO RLE,
reads them as PNG from their own URLs, and GrabCut answers with a PNG.
"""

import time

from flask import Blueprint, Response, current_app, flash, redirect, render_template, request, send_file, url_for
from flask_login import current_user

from app.blueprints import exports
from app.blueprints.frames import media_urls
from app.errors import Problem
from app.extensions import db
from app.models import HAND_LABEL, Annotation, Frame, InstanceKind, Role, Status
from app.security import roles
from app.services import exchange
from app.services import frames as frames_service
from app.services import labelling, media
from app.services.labelling import classes
from app.validation import MIB, Bool, Float, Int, List, Obj, Str, json_body, query_int, read_body, takes_json
from egonet import io as egonet_io

bp = Blueprint("label", __name__)

LABELLERS = (Role.ANNOTATOR, Role.ADMIN)
REVIEWERS = (Role.REVIEWER, Role.ADMIN)
EDITORS = (Role.ANNOTATOR, Role.REVIEWER, Role.ADMIN)  # who draws: labellers, and reviewers fixing a mask

INSTANCE = Obj(
    {
        "key": Str(min_len=1, max_len=40),
        "kind": Str(choices=[k.value for k in InstanceKind], nullable=True, default=None),
        "label": Str(max_len=120, nullable=True, default=None),
        "mask": labelling.Rle(),
    }
)
FIX = {
    "version": Int(min=0),
    "instances": List(INSTANCE, max_len=labelling.MAX_INSTANCES),
    "no_action_object": Bool(default=False),
}
SAVE = {
    **FIX,
    "status": Str(choices=[s.value for s in labelling.AUTHOR_STATUSES], nullable=True, default=None),
    "time_spent_delta_s": Float(min=0, max=labelling.MAX_TIME_DELTA_S, default=0.0),
}
VERSION = {"version": Int(min=0)}
POINT = List(Float(), min_len=2, max_len=2)
TARGET = {"frame_id": Int(min=1), "instance": Str(min_len=1, max_len=40)}
# use_depth: null or absent = the frame's depth when it has one (see labelling.grabcut_box).
BOX = {**TARGET, "box": List(Float(), min_len=4, max_len=4), "use_depth": Bool(nullable=True, default=None)}
CARRY = {"replace": Bool(default=False), "version": Int(min=0, nullable=True, default=None)}
CARRY_MAX = 50  # frames the page's "Frames" field may ask for (a chain of requests)
PROPAGATE = {**CARRY, "direction": Str(choices=["next", "previous"], default="next"),
             "count": Int(min=1, max=labelling.RANGE_MAX, default=1)}
SUGGEST = {
    "version": Int(min=0),
    "source": Str(choices=list(labelling.SUGGEST_SOURCES), default="auto"),
    "run_id": Int(min=1, nullable=True, default=None),
}
ACCEPT = {"version": Int(min=1), "key": Str(min_len=1, max_len=40)}
REVIEW = {
    "version": Int(min=1),
    "decision": Str(choices=["accept", "reject"]),
    "comment": Str(max_len=5000, nullable=True, default=None),
}


def stroke_schema() -> dict:
    """The stroke body, with as many points as GRABCUT_MAX_STROKE_POINTS allows."""
    return {
        **TARGET,
        "points": List(POINT, max_len=current_app.config["GRABCUT_MAX_STROKE_POINTS"]),
        "label": Str(choices=["fg", "bg"]),
        "radius": Float(),
        # The object's mask as the page has it: GrabCut starts from it when the user has no session of the object.
        "start": labelling.Rle(nullable=True, default=None),
    }


def me():
    """The signed-in user itself (not Flask-Login's proxy), for the services to store."""
    return current_user._get_current_object()


# --------------------------------------------------------------------------
# Pages


@bp.get("/label/")
def index():
    """The overview: an annotator's queue, a reviewer's queue (admins see both)."""
    user = me()
    queue = labelling.annotator_queue(user) if user.role in LABELLERS else None
    reviews, waiting = labelling.review_queue() if user.role in REVIEWERS else (None, 0)
    return render_template(
        "label/index.html",
        queue=queue,
        reviews=reviews,
        waiting=waiting,
        export_form=exports.form_values(request.args),
        activities=exchange.activity_names(),
        annotators=exchange.annotator_names(),
        statuses=exchange.EXPORTABLE_STATUSES,
        recent_exports=exchange.recent_exports(),
    )


def page_config(frame: Frame, *, mode: str, annotation: Annotation | None = None) -> dict:
    """What the page script needs: the frame, its media and the API's URLs."""
    config = {
        "mode": mode,
        "history_max_bytes": labelling.MAX_HISTORY_BYTES,
        # The label field completes from these (a datalist); strict: a name outside them is refused on save.
        "classes": {"names": classes.class_names(), "hand": HAND_LABEL, "strict": current_app.config["LABEL_CLASSES_STRICT"]},
        "frame": {"id": frame.id, "width": frame.width, "height": frame.height, **media_urls(frame)},
        "urls": {
            "grabcut": {
                "box": url_for("label.grabcut_box"),
                "stroke": url_for("label.grabcut_stroke"),
                "undo": url_for("label.grabcut_undo"),
                "mask": url_for("label.grabcut_mask"),
            },
        },
    }
    if mode == "label":
        previous, following = frames_service.neighbours(frame)
        config["heartbeat_s"] = labelling.HEARTBEAT_S
        config["urls"].update(
            annotation=url_for("label.own_annotation", frame_id=frame.id),
            reopen=url_for("label.reopen_annotation", frame_id=frame.id),
            presence=url_for("label.presence", frame_id=frame.id),
            time=url_for("label.add_time", frame_id=frame.id),
            previous=url_for("label.frame", frame_id=previous) if previous else None,
            next=url_for("label.frame", frame_id=following) if following else None,
            next_unlabelled=url_for("label.next_unlabelled", after=frame.id),
            propagate=url_for("label.propagate_next", frame_id=frame.id),
            copy_previous=url_for("label.copy_previous", frame_id=frame.id),
            filmstrip=url_for("label.filmstrip", frame_id=frame.id),
            suggest=url_for("label.suggest", frame_id=frame.id),
            accept_proposal=url_for("label.accept_proposal", frame_id=frame.id),
        )
        config["suggest"] = labelling.source_choices(frame)
        # The page carries up to carry_max frames as a chain of requests of at most range_max frames each.
        config["carry_max"] = CARRY_MAX
        config["carry_request"] = {"frames": labelling.RANGE_MAX, "object_frames": labelling.RANGE_OBJECT_FRAMES}
        # Whether the sequence goes on either side: Propagate and Copy are disabled (with the reason) where not.
        config["carry"] = {"next": labelling.adjacent_frame(frame, step=1) is not None,
                           "previous": labelling.adjacent_frame(frame, step=-1) is not None}
    else:
        config["own"] = annotation.author_id == current_user.id
        config["urls"].update(
            annotation=url_for("label.annotation", annotation_id=annotation.id),
            fix=url_for("label.fix_annotation", annotation_id=annotation.id),
            review=url_for("label.review_annotation", annotation_id=annotation.id),
            next_review=url_for("label.next_review", after=annotation.id),
        )
    return config


@bp.get("/label/classes")
@roles(Role.ADMIN)
def class_list():
    """The project's object classes: the names the label field completes from (admins manage them)."""
    return render_template("label/classes.html", names=classes.class_names(), strict=current_app.config["LABEL_CLASSES_STRICT"],
                           hand=HAND_LABEL)


@bp.post("/label/classes")
@roles(Role.ADMIN)
def add_classes():
    """Add the names typed in the form's ``names`` field, one a line or separated by commas."""
    text = request.form.get("names", "")
    if len(text) > 20_000:
        raise Problem("names: at most 20,000 characters at once", field="names", status=413)
    names = [n for line in text.splitlines() for n in line.split(",") if n.strip()]
    if not names:
        raise Problem("names: type at least one class name", field="names")
    added = classes.add_classes(names)
    flash(f"Added {len(added)} of {len(names)} classes." + (f" ({len(names) - len(added)} were in the list already.)" if len(added) < len(names) else ""))
    return redirect(url_for("label.class_list"))


@bp.post("/label/classes/remove")
@roles(Role.ADMIN)
def remove_class():
    name = request.form.get("name", "")
    classes.remove_class(name)
    flash(f"Removed {name.strip()!r}; labels already saved keep it.")
    return redirect(url_for("label.class_list"))


@bp.get("/label/frames/<int:frame_id>")
@roles(*LABELLERS)
def frame(frame_id: int):
    fr = db.get_or_404(Frame, frame_id)
    return render_template("label/label.html", frame=fr, label_config=page_config(fr, mode="label"), annotation=None)


@bp.get("/label/next")
@roles(*LABELLERS)
def next_unlabelled():
    """Go to the next frame the user should label (after ``after``, within ``activity``)."""
    after = query_int("after")
    activity = query_int("activity")
    after_frame = db.session.get(Frame, after) if after else None
    target = labelling.next_unlabelled(me(), after=after_frame, activity_id=activity)
    if target is None:
        flash("Nothing left to label here: every frame is labelled or being labelled by someone.", "info")
        return redirect(url_for("label.index"))
    return redirect(url_for("label.frame", frame_id=target))


@bp.get("/label/annotations/<int:annotation_id>/review")
@roles(*REVIEWERS)
def review(annotation_id: int):
    annotation = db.get_or_404(Annotation, annotation_id)
    label_config = page_config(annotation.frame, mode="review", annotation=annotation)
    return render_template("label/label.html", frame=annotation.frame, label_config=label_config, annotation=annotation)


@bp.get("/label/review/next")
@roles(*REVIEWERS)
def next_review():
    after = query_int("after")
    target = labelling.next_to_review(me(), after=db.session.get(Annotation, after) if after else None)
    if target is None:
        flash("The review queue is empty.", "info")
        return redirect(url_for("label.index"))
    return redirect(url_for("label.review", annotation_id=target))


# --------------------------------------------------------------------------
# API: the user's own annotation of a frame


def annotation_json(annotation: Annotation | None, frame: Frame) -> dict:
    """Metadata of an annotation (masks are at their URLs); a blank one at version 0."""
    body = {
        "frame_id": frame.id,
        "width": frame.width,
        "height": frame.height,
        "id": None,
        "author": None,
        "version": 0,
        "status": Status.TODO.value,
        "no_action_object": False,
        "time_spent_s": 0.0,
        "review_comment": None,
        "reviewer": None,
        "reviewed_at": None,
        "fixed_by": None,
        "fixed_at": None,
        "updated_at": None,
        "history_url": None,
        "mask_url": None,
        "proposed_by_run_id": None,
        "proposed_by_checkpoint_id": None,
        "instances": [],
    }
    if annotation is None:
        return body
    body.update(
        id=annotation.id,
        author=annotation.author.username,
        version=annotation.version,
        status=annotation.status.value,
        no_action_object=annotation.no_action_object,
        time_spent_s=round(annotation.time_spent_s, 3),
        review_comment=annotation.review_comment,
        reviewer=annotation.reviewer.username if annotation.reviewer else None,
        reviewed_at=annotation.reviewed_at.isoformat() if annotation.reviewed_at else None,
        fixed_by=annotation.fixed_by.username if annotation.fixed_by else None,
        fixed_at=annotation.fixed_at.isoformat() if annotation.fixed_at else None,
        updated_at=annotation.updated_at.isoformat(),
        history_url=url_for("label.history", annotation_id=annotation.id),
        mask_url=url_for("label.annotation_mask", annotation_id=annotation.id) if annotation.mask_path else None,
        proposed_by_run_id=annotation.proposed_by_run_id,
        proposed_by_checkpoint_id=annotation.proposed_by_checkpoint_id,
        instances=[
            {
                "position": i.position,
                "key": i.key,
                "kind": i.kind.value if i.kind else None,
                "label": i.label,
                "mask_url": url_for("label.instance_mask", annotation_id=annotation.id, position=i.position),
                # Set while the instance is a proposal, not accepted or edited yet: its source, and its run.
                "proposal_source": i.proposal_source,
                "proposed_by_run_id": i.proposed_by_run_id,
                "proposed_by_checkpoint_id": i.proposed_by_checkpoint_id,
            }
            for i in annotation.instances
        ],
    )
    return body


@bp.get("/api/label/frames/<int:frame_id>/annotation")
@roles(*LABELLERS)
def own_annotation(frame_id: int):
    fr = labelling.get_frame(frame_id)
    body = annotation_json(labelling.user_annotation(fr, me()), fr)
    body["grabcut"] = labelling.grabcut_keys(fr, me())
    return body


@bp.put("/api/label/frames/<int:frame_id>/annotation")
@roles(*LABELLERS)
@takes_json(8 * MIB)
def save_annotation(frame_id: int):
    """Save with a version check: 409 with ``current_version`` when stale."""
    data = json_body(SAVE)
    fr = labelling.get_frame(frame_id)
    annotation = labelling.save_annotation(fr, me(), data)
    return annotation_json(annotation, fr)


@bp.post("/api/label/frames/<int:frame_id>/annotation/reopen")
@roles(*LABELLERS)
@takes_json()
def reopen_annotation(frame_id: int):
    """``{version}``: put the user's done or reviewed annotation back in progress ("Edit")."""
    data = json_body(VERSION)
    fr = labelling.get_frame(frame_id)
    return annotation_json(labelling.reopen_annotation(fr, me(), version=data["version"]), fr)


@bp.post("/api/label/frames/<int:frame_id>/presence")
@roles(*LABELLERS)
@takes_json()
def presence(frame_id: int):
    """``{open}``: the user has the frame open (true, every HEARTBEAT_S) or left it (false);
    answers who else is on the frame (``others``: open, or with an annotation of it)."""
    data = json_body({"open": Bool()})
    fr = labelling.get_frame(frame_id)
    if data["open"]:
        labelling.mark_present(fr, me())
    else:
        labelling.leave(fr, me())
    return {"others": [h.to_dict() for h in labelling.others_on(fr, me())], "ttl_s": labelling.PRESENCE_TTL_S}


@bp.post("/api/label/frames/<int:frame_id>/annotation/time")
@roles(*LABELLERS)
@takes_json()
def add_time(frame_id: int):
    """``{seconds}`` spent on the frame since the last save; no new version (204)."""
    data = json_body({"seconds": Float(min=0, max=labelling.MAX_TIME_DELTA_S)})
    fr = labelling.get_frame(frame_id)
    if not labelling.add_time(fr, me(), data["seconds"]):
        raise Problem("you have no annotation of this frame yet", status=404, fields={"frame_id": "no annotation"})
    return "", 204


@bp.post("/api/label/frames/<int:frame_id>/suggest")
@roles(*LABELLERS)
@takes_json()
def suggest(frame_id: int):
    """``{version, source?, run_id?}``: a trained run, or a source that needs none (depth, handled,
    saliency), proposes the frame's action-objects into the user's annotation; ``source`` "auto" (the
    default) chooses by evidence: a run for frames like this one, else depth, else handled (see proposers.auto_choice).

    200 with ``{annotation, suggestion}`` when it ran here; 202 with
    ``{queued: true, message}`` when the model is slow here and the worker
    has it. 409 for a stale version, a done annotation, depth asked of a
    frame without it, or the model source without a trained run.
    """
    data = json_body(SUGGEST)
    fr = labelling.get_frame(frame_id)
    result = labelling.suggest_from_page(fr, me(), run_id=data["run_id"], source=data["source"], version=data["version"])
    if isinstance(result, labelling.Queued):
        return {"queued": True, "message": result.summary(), "run_id": result.proposer.run.id}, 202
    return {
        "annotation": annotation_json(result.annotation, fr),
        "suggestion": result.to_dict() | {"message": result.summary()},
    }


@bp.post("/api/label/frames/<int:frame_id>/annotation/proposals/accept")
@roles(*LABELLERS)
@takes_json()
def accept_proposal(frame_id: int):
    """``{version, key}``: accept the model's proposal ``key``; it becomes an ordinary instance (new version)."""
    data = json_body(ACCEPT)
    fr = labelling.get_frame(frame_id)
    annotation = labelling.accept_proposal(fr, me(), key=data["key"], version=data["version"])
    return annotation_json(annotation, fr)


# --------------------------------------------------------------------------
# API: carrying an annotation between adjacent frames, the sequence's filmstrip


@bp.post("/api/label/frames/<int:frame_id>/propagate")
@roles(*LABELLERS)
@takes_json()
def propagate_next(frame_id: int):
    """``{replace, version, direction, count}`` -> the last carried frame's new
    annotation, with ``url`` to label it, ``carried`` (each frame's id and
    number, in order) and ``stopped`` (``{kind, frame_id, index, reason}``
    when the range ended early, else null).

    ``direction`` ``next`` (default) or ``previous``, ``count`` 1-10 frames
    (default 1). 409 when the first target has the user's work (``replace``
    with its ``version`` replaces unfinished work), 404 ``next`` / ``previous``
    at the sequence's end, 400 ``count`` over the bounds.
    """
    data = json_body(PROPAGATE)
    fr = labelling.get_frame(frame_id)
    run = labelling.propagate(fr, me(), step=1 if data["direction"] == "next" else -1, count=data["count"],
                              replace=data["replace"], version=data["version"])
    last = run.annotations[-1]
    stop = run.stop
    return {
        **annotation_json(last, last.frame),
        "url": url_for("label.frame", frame_id=last.frame_id),
        "carried": [{"frame_id": a.frame_id, "index": a.frame.index} for a in run.annotations],
        "stopped": stop and {"kind": stop.kind, "frame_id": stop.frame.id, "index": stop.frame.index,
                             "reason": stop.reason},
    }


@bp.post("/api/label/frames/<int:frame_id>/copy-previous")
@roles(*LABELLERS)
@takes_json()
def copy_previous(frame_id: int):
    """``{replace, version}`` -> this frame's annotation, carried over from the previous frame."""
    data = json_body(CARRY)
    fr = labelling.get_frame(frame_id)
    annotation = labelling.copy_from_previous(fr, me(), replace=data["replace"], version=data["version"])
    return annotation_json(annotation, fr)


@bp.get("/api/label/frames/<int:frame_id>/filmstrip")
@roles(*LABELLERS)
def filmstrip(frame_id: int):
    """A window of the frame's sequence: ``?start=`` (position) or ``?at=`` (a frame's index), ``?count=``."""
    fr = labelling.get_frame(frame_id)
    count = query_int("count", min=1, max=labelling.FILMSTRIP_MAX)
    strip = labelling.filmstrip(fr, at_index=query_int("at", min=0), start=query_int("start", min=0),
                                count=count or 41)
    return {
        "sequence": fr.sequence.name,
        "total": strip.total,
        "start": strip.start,
        "focus": {"id": strip.focus.id, "index": strip.focus.index, "position": strip.focus_position,
                  "url": url_for("label.frame", frame_id=strip.focus.id)},
        "frames": [
            {
                "id": f.id,
                "index": f.index,
                "status": strip.statuses[f.id].value,
                "thumb_url": url_for("frames.thumbnail", frame_id=f.id),
                "url": url_for("label.frame", frame_id=f.id),
            }
            for f in strip.frames
        ],
    }


# --------------------------------------------------------------------------
# API: any annotation, by id


@bp.get("/api/label/annotations/<int:annotation_id>")
def annotation(annotation_id: int):
    ann = labelling.get_annotation(annotation_id)
    return annotation_json(ann, ann.frame)


@bp.get("/api/label/annotations/<int:annotation_id>/mask.png")
def annotation_mask(annotation_id: int):
    """The union of the instances' masks (all black when nothing is drawn)."""
    ann = labelling.get_annotation(annotation_id)
    if ann.mask_path is None:
        return png_response(labelling.empty_mask(ann.frame))
    return _mask_file(ann.mask_path)


@bp.get("/api/label/annotations/<int:annotation_id>/thumb.png")
def annotation_thumbnail(annotation_id: int):
    """The instances over a transparent background, at the frame thumbnail's size (the queues' tiles).

    Its URL carries ``?v=<version>``, so a browser may keep it: a new version is a new URL.
    """
    ann = labelling.get_annotation(annotation_id)
    return send_file(labelling.mask_thumbnail(ann), mimetype="image/png", max_age=86400)


@bp.get("/api/label/annotations/<int:annotation_id>/instances/<int:position>/mask.png")
def instance_mask(annotation_id: int, position: int):
    ann = labelling.get_annotation(annotation_id)
    return _mask_file(labelling.instance_of(ann, position).mask_path)


@bp.put("/api/label/annotations/<int:annotation_id>/instances/<int:position>/mask.png")
@roles(*LABELLERS)
def upload_instance_mask(annotation_id: int, position: int):
    """Replace an instance's mask with the PNG body (``?version=N`` required)."""
    version = query_int("version", min=0)
    if version is None:
        raise Problem("version: give the annotation's version as ?version=N", fields={"version": "is required"})
    if request.mimetype != "image/png":
        raise Problem("send the mask as a PNG body (Content-Type: image/png)", status=415,
                      fields={"mask": "must be image/png"})
    ann = labelling.get_annotation(annotation_id)
    ann = labelling.upload_instance_mask(ann, me(), position=position, version=version, png=request.get_data())
    return annotation_json(ann, ann.frame)


@bp.put("/api/label/annotations/<int:annotation_id>")
@roles(*REVIEWERS)
@takes_json(8 * MIB)
def fix_annotation(annotation_id: int):
    """A reviewer's fix of a done annotation's masks (``{version, instances, no_action_object}``), before deciding."""
    data = json_body(FIX)
    ann = labelling.fix_annotation(labelling.get_annotation(annotation_id), me(), data)
    return annotation_json(ann, ann.frame)


@bp.get("/api/label/annotations/<int:annotation_id>/history")
@roles(*EDITORS)
def history(annotation_id: int):
    """The user's undo history of the annotation as the page stored it (gzip), 404 without one;
    ``X-Annotation-Version`` is the version it ends at."""
    row = labelling.get_history(labelling.get_annotation(annotation_id), me())
    if row is None:
        raise Problem("no undo history kept for this annotation", status=404, fields={"history": "none"})
    response = Response(row.data, mimetype="application/gzip")
    response.headers["Cache-Control"] = "no-store"
    response.headers["X-Annotation-Version"] = str(row.version)
    return response


@bp.put("/api/label/annotations/<int:annotation_id>/history")
@roles(*EDITORS)
def put_history(annotation_id: int):
    """Store the page's undo history (gzip body, ``?version=N``: the annotation's version it ends at); 204."""
    version = query_int("version", min=1)
    if version is None:
        raise Problem("version: give the annotation's version as ?version=N", fields={"version": "is required"})
    data = read_body(labelling.MAX_HISTORY_BYTES, field="history")
    labelling.put_history(labelling.get_annotation(annotation_id), me(), version=version, data=data)
    return "", 204


@bp.post("/api/label/annotations/<int:annotation_id>/review")
@roles(*REVIEWERS)
@takes_json()
def review_annotation(annotation_id: int):
    data = json_body(REVIEW)
    ann = labelling.get_annotation(annotation_id)
    ann = labelling.review_annotation(
        ann, me(), version=data["version"], decision=data["decision"], comment=data["comment"]
    )
    return annotation_json(ann, ann.frame)


def _mask_file(relative: str):
    # Revalidated on every use (ETag), since an instance's mask changes under the same URL.
    return send_file(media.local_path(relative), mimetype="image/png", max_age=0, etag=True, conditional=True)


# --------------------------------------------------------------------------
# API: GrabCut, on the server, one session per user, frame and instance
# (a reviewer fixing a done annotation has sessions of their own on its frame)


def _clock() -> tuple[float, float]:
    """Wall clock and this thread's CPU time, for ``png_response``'s Server-Timing."""
    return time.perf_counter(), time.thread_time()


def png_response(mask, *, can_undo: bool | None = None, started: tuple[float, float] | None = None) -> Response:
    response = Response(egonet_io.encode_png(mask), mimetype="image/png")
    response.headers["Cache-Control"] = "no-store"
    if can_undo is not None:
        response.headers["X-Can-Undo"] = "1" if can_undo else "0"
    if started is not None:
        wall, cpu = started
        response.headers["Server-Timing"] = (f"grabcut;dur={1000 * (time.perf_counter() - wall):.1f}, "
                                             f"cpu;dur={1000 * (time.thread_time() - cpu):.1f}")
    return response


def _target(data: dict) -> tuple[Frame, str]:
    """The frame and object of a GrabCut step; 409 while the user's annotation of the frame is finished."""
    fr = labelling.get_frame(data["frame_id"], field="frame_id")
    key = labelling.check_key(data["instance"])
    labelling.check_open_frame(fr, me())
    return fr, key


@bp.post("/api/label/grabcut/box")
@roles(*EDITORS)
@takes_json()
def grabcut_box():
    """``{frame_id, instance, box: [x0, y0, x1, y1], use_depth?}`` -> the object's first mask (PNG)."""
    started = _clock()
    data = json_body(BOX)
    fr, key = _target(data)
    box = labelling.check_box(fr, data["box"])
    result = labelling.grabcut_box(fr, me(), key, box, use_depth=data["use_depth"])
    return png_response(result.mask, can_undo=result.can_undo, started=started)


@bp.post("/api/label/grabcut/stroke")
@roles(*EDITORS)
@takes_json(MIB)
def grabcut_stroke():
    """``{frame_id, instance, points: [[x, y], ...], label: fg|bg, radius, start?}`` -> the updated mask (PNG);
    ``start`` (RLE, the object's mask) starts GrabCut from it when the user has no session of the object."""
    started = _clock()
    data = json_body(stroke_schema())
    fr, key = _target(data)
    labelling.check_stroke(fr, data["points"], data["radius"])
    start = None if data["start"] is None else labelling.decode_rle(data["start"], (fr.height, fr.width), field="start")
    result = labelling.grabcut_stroke(fr, me(), key, points=data["points"], label=data["label"],
                                      radius=data["radius"], start=start)
    return png_response(result.mask, can_undo=result.can_undo, started=started)


@bp.post("/api/label/grabcut/undo")
@roles(*EDITORS)
@takes_json()
def grabcut_undo():
    """``{frame_id, instance}`` -> the mask before the last GrabCut operation (PNG)."""
    started = _clock()
    fr, key = _target(json_body(TARGET))
    result = labelling.grabcut_undo(fr, me(), key)
    return png_response(result.mask, can_undo=result.can_undo, started=started)


@bp.get("/api/label/grabcut/mask.png")
@roles(*EDITORS)
def grabcut_mask():
    """``?frame_id=&instance=`` -> the session's current mask (PNG), 404 without a session."""
    frame_id = query_int("frame_id")
    if frame_id is None:
        raise Problem("frame_id: give ?frame_id=N", fields={"frame_id": "is required"})
    fr = labelling.get_frame(frame_id, field="frame_id")
    key = labelling.check_key(request.args.get("instance", ""))
    result = labelling.grabcut_mask(fr, me(), key)
    return png_response(result.mask, can_undo=result.can_undo)
