"""SQLAlchemy models, one module per area; import them from here."""

from app.models.annotations import FINISHED, Annotation, Instance, InstanceKind, Status
from app.models.base import Base, utcnow
from app.models.frames import Activity, Frame, Sequence
from app.models.users import Role, User

__all__ = [
    "FINISHED",
    "Activity",
    "Annotation",
    "Base",
    "Frame",
    "Instance",
    "InstanceKind",
    "Role",
    "Sequence",
    "Status",
    "User",
    "utcnow",
]
