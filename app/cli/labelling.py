"""Labelling commands (export)."""

from app.cli import bp  # noqa: F401
