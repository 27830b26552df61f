"""Scoring commands (score)."""

from app.cli import bp  # noqa: F401
