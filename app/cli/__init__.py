"""The ``flask egonet`` command group: thin wrappers over the services.

Each area adds its commands in its own module (data.py, training.py, ...),
all on the one group below. Every failure exits non-zero with a one-line
reason (click's "Error: ...").
"""

import contextlib

import click
from flask import Blueprint

bp = Blueprint("egonet_cli", __name__, cli_group="egonet")


@contextlib.contextmanager
def one_line_errors():
    """Turn the services' validation errors into click's one-line failure."""
    try:
        yield
    except ValueError as exc:  # MediaError, ImportProblem, UserProblem are ValueErrors
        raise click.ClickException(str(exc)) from None


@contextlib.contextmanager
def progress_bar(label: str, *, file=None):
    """Yield (on_start, on_progress) callbacks that drive a click progress bar.

    ``file`` defaults to stdout; commands whose stdout is data (CSV, JSON)
    pass ``sys.stderr``.
    """
    state: dict = {}

    def on_start(total: int) -> None:
        state["bar"] = click.progressbar(length=total, label=label, show_eta=True, show_pos=True, file=file)
        state["bar"].__enter__()

    def on_progress(n: int) -> None:
        if "bar" not in state:
            on_start(0)
        state["bar"].update(n)

    try:
        yield on_start, on_progress
    finally:
        if "bar" in state:
            state["bar"].__exit__(None, None, None)


# Register the commands of every area on the group.
from app.cli import data, labelling, scoring, studies, training, users  # noqa: E402, F401
