"""Training commands (train, predict) and the worker."""

import click
from flask import current_app

from app.cli import bp


@bp.cli.command("worker")
@click.option("--workers", type=click.IntRange(min=1, max=16), default=1, show_default=True)
def worker_command(workers):
    """Run the task-queue worker (training, batch prediction) until Ctrl-C."""
    from app.tasks import huey, run_worker

    click.echo(f"worker: {type(huey.storage).__name__} queue, {workers} worker(s); Ctrl-C to stop")
    run_worker(current_app._get_current_object(), workers=workers)
