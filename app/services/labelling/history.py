"""The labelling page's undo / redo history, kept on the server.

The page sends its whole history after each save that moved the
annotation's version on (``put_history``), and reads it back when it opens
the frame (``get_history``), so Ctrl+Z reaches past a reload, a restart of
the server or the browser, and works from another browser. The history is
the page's own format (gzip-compressed JSON of the document's snapshots,
masks as row runs; ``static/js/history.js``): the server never decodes it,
it only bounds its size and checks the version.

Each history records the annotation version it ends at. A history written
at a version older than the annotation's (the last write was lost with the
page, or someone else saved since) is still handed back with its version;
the page then bridges the gap with one undoable step, as it does when it
loads a newer saved version.

A history is one person's: the annotation's author, or a reviewer fixing a
done annotation (``review.fix_annotation``). Reviewing an annotation deletes
the reviewer's history of it; the author's stays, accepted or not.
"""

from app.errors import Problem
from app.extensions import db
from app.models import Annotation, Role, Status, User
from app.models.annotations import EditHistory
from app.services.labelling.annotations import stale

MAX_HISTORY_BYTES = 4 * 1024 * 1024  # what one history may take, compressed


def _may_keep(annotation: Annotation, user: User) -> None:
    fixing = user.role in (Role.REVIEWER, Role.ADMIN) and annotation.status is Status.DONE
    if annotation.author_id != user.id and not fixing:
        raise Problem("only an annotation's author, or a reviewer fixing it, keeps an undo history of it",
                      status=403, fields={"annotation_id": "not yours to edit"})


def get_history(annotation: Annotation, user: User) -> EditHistory | None:
    """The user's stored history of the annotation, if any."""
    return db.session.execute(
        db.select(EditHistory).filter_by(annotation_id=annotation.id, user_id=user.id)
    ).scalar_one_or_none()


def put_history(annotation: Annotation, user: User, *, version: int, data: bytes) -> EditHistory | None:
    """Store the user's history of the annotation as it stands at ``version``
    (empty ``data`` deletes it; returns None then).

    Raises:
        Problem: 403 when the user may not edit the annotation, 409 when
            ``version`` is not the annotation's current one, 413 when ``data``
            is over MAX_HISTORY_BYTES.
    """
    _may_keep(annotation, user)
    if version != annotation.version:
        raise stale(annotation.version)
    if len(data) > MAX_HISTORY_BYTES:
        raise Problem(f"history: {len(data)} bytes, more than the {MAX_HISTORY_BYTES} an undo history may take; "
                      "send fewer steps", status=413, fields={"history": f"over {MAX_HISTORY_BYTES} bytes"})
    row = get_history(annotation, user)
    if not data:
        if row is not None:
            db.session.delete(row)
            db.session.commit()
        return None
    if row is None:
        row = EditHistory(annotation_id=annotation.id, user_id=user.id, version=version, data=data)
        db.session.add(row)
    else:
        row.version, row.data = version, data
    db.session.commit()
    return row


def forget_histories(annotation: Annotation, *, user: User | None = None) -> None:
    """Delete the histories of the annotation (only ``user``'s when given), in the caller's transaction."""
    query = db.delete(EditHistory).where(EditHistory.annotation_id == annotation.id)
    if user is not None:
        query = query.where(EditHistory.user_id == user.id)
    db.session.execute(query)
