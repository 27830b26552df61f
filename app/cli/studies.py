"""Human-study commands."""

from app.cli import bp  # noqa: F401
