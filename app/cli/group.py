"""The ``flask egonet`` group that every area's commands join, and their progress bar."""

import contextlib

import click
from flask import Blueprint
from flask.cli import AppGroup

from app.errors import Problem
from app.services.storage import StorageProblem, StorageUnavailable
from egonet.errors import EgonetError


class EgonetGroup(AppGroup):
    """The command group; its one handler prints a ``Problem``, ``EgonetError`` or storage failure as one line."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except (Problem, EgonetError, StorageProblem, StorageUnavailable) as exc:
            raise click.ClickException(str(exc)) from None


bp = Blueprint("egonet_cli", __name__, cli_group="egonet")
bp.cli = EgonetGroup()


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
