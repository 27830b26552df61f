"""SQLAlchemy models, one module per area; import them from here."""

from app.models.annotations import FINISHED, HAND_LABEL, Annotation, AttentionPoints, Instance, InstanceKind, ObjectClass, Status, is_hand
from app.models.base import Base, utcnow
from app.models.frames import Activity, Frame, Sequence
from app.models.users import Role, User

# Every model module is imported here so the metadata (and Alembic) sees it.
from app.models import exports, studies, training  # noqa: E402, F401

__all__ = [
    "FINISHED",
    "HAND_LABEL",
    "Activity",
    "Annotation",
    "AttentionPoints",
    "Base",
    "Frame",
    "Instance",
    "InstanceKind",
    "ObjectClass",
    "Role",
    "Sequence",
    "Status",
    "User",
    "is_hand",
    "utcnow",
]
