"""The ``flask egonet`` command group: thin wrappers over the services.

Each area adds its commands in its own module (data.py, training.py, ...),
all on the one group of ``app.cli.group``. A ``Problem``, ``EgonetError`` or storage
failure raised by a command exits non-zero with a one-line reason (click's "Error: ...").
"""

from app.cli import data, labelling, scoring, studies, training, users  # noqa: F401  (they register their commands)
from app.cli.group import bp  # noqa: F401
