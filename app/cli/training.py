"""Training commands (train, predict) and the worker."""

import re
from pathlib import Path

import click

from app.cli import bp, progress_bar
from app.queue import current_huey, enqueue, run_worker


def _size(ctx, param, value: str) -> tuple[int, int]:
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", value or "")
    if not match:
        raise click.BadParameter(f"use WIDTHxHEIGHT, e.g. 320x240 (got {value!r})")
    return int(match.group(1)), int(match.group(2))


def _duration(seconds: float | None) -> str:
    if seconds is None:
        return "--:--"
    seconds = int(seconds)
    hours, rest = divmod(seconds, 3600)
    return f"{hours}:{rest // 60:02d}:{rest % 60:02d}" if hours else f"{rest // 60:02d}:{rest % 60:02d}"


class TrainingBar:
    """A click progress bar over the run's steps, showing fold, epoch, loss and the engine's ETA."""

    def __init__(self):
        self.bar = None
        self.text = ""

    def __call__(self, progress) -> None:
        if self.bar is None:
            self.bar = click.progressbar(
                length=max(progress.steps, 1), label="Training", show_eta=False, show_pos=True,
                item_show_func=lambda _: self.text,
            )
            self.bar.__enter__()
        loss = f"loss {progress.loss:.4f}" if progress.loss is not None else "loss -"
        self.text = (
            f"{progress.fold} {progress.fold_index + 1}/{progress.folds} "
            f"epoch {progress.epoch}/{progress.epochs} {loss} ETA {_duration(progress.eta_s)}"
        )
        self.bar.update(progress.step - self.bar.pos)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.__exit__(None, None, None)


@bp.cli.command("train")
@click.option("--model", default="egonet-lite", show_default=True, help="Network variant (egonet, egonet-lite, egonet-rgb, ...).")
@click.option("--folds", type=click.Choice(["loao", "single"]), default="loao", show_default=True,
              help="loao: one model per held-out activity; single: one model, last 20% of each activity held out.")
@click.option("--epochs", type=click.IntRange(min=1), default=10, show_default=True)
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--size", default="320x240", show_default=True, callback=_size, help="Training size WIDTHxHEIGHT.")
@click.option("--lr", type=click.FloatRange(min=0, min_open=True), help="Learning rate for the mean loss [default: per model].")
@click.option("--batch-size", type=click.IntRange(min=1), default=4, show_default=True)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
@click.option("--pretrained", is_flag=True, help="Start egonet-lite from ImageNet weights (needs the pretrained extra).")
@click.option("--activities", "activities", multiple=True, help="Train on these activities only (repeat the option; default: all).")
@click.option("--name", help="Name of the run.")
@click.option("--resume", "resume", type=int, metavar="CHECKPOINT_ID",
              help="Continue a checkpoint's fold with its own settings, up to --epochs in all.")
@click.option("--queue", is_flag=True, help="Queue the run for `flask egonet worker` instead of training here.")
def train_command(model, folds, epochs, device, size, lr, batch_size, seed, pretrained, activities, name, resume, queue):
    """Train EgoNet on the frames with done or reviewed annotations.

    Records a training run with a checkpoint per fold and a prediction for
    every held-out frame. Under torchrun, every process trains its share.
    """
    from app.extensions import db
    from app.models import Activity
    from app.models.training import Checkpoint
    from app.services.training import (
        RunRequest,
        start_run,
        train_in_foreground,
    )

    checkpoint = None
    if resume is not None:
        checkpoint = db.session.get(Checkpoint, resume)
        if checkpoint is None:
            raise click.ClickException(f"no checkpoint with id {resume}")
    activity_ids = None
    if activities:
        found = dict(db.session.execute(db.select(Activity.name, Activity.id).where(Activity.name.in_(activities))).all())
        missing = [a for a in activities if a not in found]
        if missing:
            raise click.ClickException(f"no activity named {', '.join(map(repr, missing))}")
        activity_ids = tuple(found[a] for a in activities)
    request = RunRequest(
        model=model, folds=folds, epochs=epochs, device=device, width=size[0], height=size[1], lr=lr,
        batch_size=batch_size, seed=seed, pretrained=pretrained, activity_ids=activity_ids, name=name,
        resume_from=checkpoint,
    )
    if queue:
        run = start_run(request)
        click.echo(f"run {run.id} queued: start `flask egonet worker` to train it")
        return
    bar = TrainingBar()
    try:
        run = train_in_foreground(request, on_progress=bar)
    finally:
        bar.close()
    if run is None:
        return
    click.echo(f"run {run.id} ({run.name}): {run.status.value}")
    for fold, scores in run.metrics.get("folds", {}).items():
        click.echo(_scores_line(fold, scores))
    if run.metrics.get("mean"):
        click.echo(_scores_line("mean", run.metrics["mean"]))
    if run.status.value != "done":
        raise click.ClickException(run.message or f"run {run.id} {run.status.value}")


def _scores_line(name: str, scores: dict) -> str:
    def f(key):
        return f"{scores[key]:.3f}" if scores.get(key) is not None else "-"

    return f"  {name:<14} MF {f('max_f')}  AP {f('ap')}   (action-object prior: MF {f('aop_max_f')}  AP {f('aop_ap')})"


@bp.cli.command("predict")
@click.argument("checkpoint_id", type=int)
@click.option("--activity", "activities", multiple=True, help="Predict the frames of this activity (repeatable).")
@click.option("--frames", "frames", help="Comma-separated frame ids.")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--queue", is_flag=True, help="Queue the job for `flask egonet worker`.")
def predict_command(checkpoint_id, activities, frames, device, queue):
    """Run checkpoint CHECKPOINT_ID on frames (all frames unless --activity/--frames say which).

    The probability maps are stored and shown in the frame viewer.
    """
    from app.extensions import db
    from app.models.training import Checkpoint
    from app.services.training import frames_for_prediction, predict

    checkpoint = db.session.get(Checkpoint, checkpoint_id)
    if checkpoint is None:
        raise click.ClickException(f"no checkpoint with id {checkpoint_id}")
    try:
        frame_ids = [int(x) for x in frames.split(",") if x.strip()] if frames else []
    except ValueError:
        raise click.BadParameter("give frame ids separated by commas, e.g. 3,4,10", param_hint="--frames") from None
    chosen = frames_for_prediction(activity_names=activities, frame_ids=frame_ids)
    if queue:
        enqueue("predict_frames", checkpoint.id, [f.id for f in chosen], device)
        click.echo(f"{len(chosen)} frames queued for checkpoint {checkpoint.id}: start `flask egonet worker`")
        return
    with progress_bar("Predicting") as (on_start, on_progress):
        on_start(len(chosen))
        made = predict(checkpoint, chosen, device=device, on_progress=on_progress)
    held_out = sum(p.held_out for p in made)
    click.echo(f"checkpoint {checkpoint.id} ({checkpoint.fold}): {len(made)} predictions stored, {held_out} of held-out frames")


@bp.cli.command("import-weights")
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--name", help="Name of the run [default: the release and the file's name].")
@click.option("--size", default="641x481", show_default=True, callback=_size,
              help="Frames are run at WIDTHxHEIGHT (the release's deploy size by default).")
def import_weights_command(file, name, size):
    """Register the authors' released EgoNet weights (FILE.caffemodel) as a model with a checkpoint.

    RGB+DHG or RGB only, recognised from the file; no Caffe needed. The
    run then predicts (`flask egonet predict CHECKPOINT_ID`), shows in the
    frame viewer, on the Scores page ("released model", every frame held
    out) and proposes objects (Suggest) like a trained one.
    """
    from app.services.training import import_in_foreground

    with progress_bar("Reading weights") as (on_start, on_progress):
        state = {"done": 0, "started": False}

        def progress(done: int, total: int) -> None:
            if not state["started"]:
                on_start(total)
                state["started"] = True
            on_progress(done - state["done"])
            state["done"] = done

        run = import_in_foreground(file, name=name, size=(size[1], size[0]), on_progress=progress)
    if run.status.value != "done":
        raise click.ClickException(run.message or f"run {run.id} {run.status.value}")
    checkpoint = run.checkpoints[0]
    click.echo(f"run {run.id} ({run.name}): {run.config['released']['title']}, model {run.model_name}, "
               f"checkpoint {checkpoint.id} ({checkpoint.path})")
    click.echo(f"next: flask --app app egonet predict {checkpoint.id} [--activity NAME] [--queue]"
               " (the Scores page scores it on every frame it has predicted)")


@bp.cli.command("worker")
@click.option("--workers", type=click.IntRange(min=1, max=16), default=1, show_default=True)
def worker_command(workers):
    """Run the task-queue worker (training, batch prediction) until Ctrl-C."""
    click.echo(f"worker: {type(current_huey().storage).__name__} queue, {workers} worker(s); Ctrl-C to stop")
    run_worker(workers=workers)
