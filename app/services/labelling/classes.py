"""The project-wide list of object classes: what the label field completes from, and what it may refuse.

Admins manage the list (the Classes page, ``flask egonet classes``); the
labelling page offers its names as completions of an instance's label. With
``LABEL_CLASSES_STRICT`` false (the default) a label outside the list is
saved as typed, so a new object never blocks labelling; true refuses it (400
naming the instance's label), so a project whose classes train DeepLab-Obj
keeps one spelling per class. :data:`~app.models.HAND_LABEL` is always allowed:
it outlines hands, not an object (``egonet.hands``).
"""

from __future__ import annotations

from collections.abc import Sequence

from flask import current_app
from sqlalchemy.exc import IntegrityError

from app.errors import Problem
from app.extensions import db
from app.models import HAND_LABEL, ObjectClass, is_hand

MAX_NAME = 120
MAX_CLASSES = 1000


def class_names() -> list[str]:
    """The list's names, in alphabetical order (case-insensitive)."""
    names = db.session.execute(db.select(ObjectClass.name)).scalars()
    return sorted(names, key=str.casefold)


def add_classes(names: Sequence[str]) -> list[str]:
    """Add names to the list (outer spaces dropped); those already there (any case) are left as they are.

    Returns:
        The names added.

    Raises:
        Problem: A name empty or over 120 characters, or the list would pass 1000 names (field ``name``).
    """
    known = {n.casefold() for n in class_names()}
    added: list[str] = []
    for raw in names:
        name = " ".join(raw.split())
        if not name or len(name) > MAX_NAME:
            raise Problem(f"name: a class name has 1 to {MAX_NAME} characters, got {raw!r}", field="name")
        if name.casefold() not in known:
            known.add(name.casefold())
            added.append(name)
    if len(known) > MAX_CLASSES:
        raise Problem(f"name: the list holds at most {MAX_CLASSES} classes", field="name")
    db.session.add_all(ObjectClass(name=name) for name in added)
    try:
        db.session.commit()
    except IntegrityError:  # added concurrently by someone else
        db.session.rollback()
        raise Problem("name: another admin changed the list at the same time; try again", field="name", status=409) from None
    return added


def remove_class(name: str) -> None:
    """Take a name off the list (labels already saved keep it).

    Raises:
        Problem: 404 when the list has no such name.
    """
    row = db.session.execute(db.select(ObjectClass).where(db.func.lower(ObjectClass.name) == name.strip().lower())).scalar()
    if row is None:
        raise Problem(f"name: the class list has no {name.strip()!r}", field="name", status=404)
    db.session.delete(row)
    db.session.commit()


def check_labels(labels: Sequence[str | None]) -> None:
    """Refuse a label outside the list when ``LABEL_CLASSES_STRICT`` is on (empty labels and ``hand`` always pass).

    Raises:
        Problem: 400 naming ``instances[i].label``.
    """
    if not current_app.config["LABEL_CLASSES_STRICT"]:
        return
    known = {n.casefold() for n in class_names()}
    for i, label in enumerate(labels):
        if label and not is_hand(label) and label.casefold() not in known:
            raise Problem(
                f"instances[{i}].label: {label!r} is not in the project's class list; choose one of its names "
                f"(or {HAND_LABEL!r} for hands), or ask an admin to add it",
                fields={f"instances[{i}].label": "not in the class list"},
            )
