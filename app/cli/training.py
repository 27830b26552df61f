"""Training commands (train, predict, worker)."""

from app.cli import bp  # noqa: F401
