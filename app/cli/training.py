"""Training commands (train, predict) and the worker."""

import re
from pathlib import Path

import click

from app.cli.group import bp, progress_bar
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
@click.option("--folds", type=click.Choice(["loao", "single", "all"]), default="loao", show_default=True,
              help="loao: one model per held-out activity; single: one model, last 20% of each activity held out; "
                   "all: one model on every labelled frame, none held out (then predict other activities).")
@click.option("--epochs", type=click.IntRange(min=1), default=10, show_default=True)
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--size", default="320x240", show_default=True, callback=_size, help="Training size WIDTHxHEIGHT.")
@click.option("--lr", type=click.FloatRange(min=0, min_open=True), help="Learning rate for the mean loss [default: per model].")
@click.option("--batch-size", type=click.IntRange(min=1), default=4, show_default=True)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
@click.option("--pretrained", is_flag=True, help="Start egonet-lite from ImageNet weights (needs the pretrained extra).")
@click.option("--init", "init", type=click.Path(dir_okay=False), metavar="FILE",
              help="Start every VGG stream from ImageNet: a torchvision vgg16-*.pth state dict or a DeepLab .caffemodel.")
@click.option("--activities", "activities", multiple=True, help="Train on these activities only (repeat the option; default: all).")
@click.option("--name", help="Name of the run.")
@click.option("--resume", "resume", type=int, metavar="CHECKPOINT_ID",
              help="Continue a checkpoint's fold with its own settings, up to --epochs in all.")
@click.option("--queue", is_flag=True, help="Queue the run for `flask egonet worker` instead of training here.")
def train_command(model, folds, epochs, device, size, lr, batch_size, seed, pretrained, init, activities, name, resume, queue):
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
        trained_on,
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
        batch_size=batch_size, seed=seed, pretrained=pretrained, init=init, activity_ids=activity_ids, name=name,
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
        if scores.get("test_frames") != 0:  # a run on every frame has no held-out scores
            click.echo(_scores_line(fold, scores))
    if run.metrics.get("mean"):
        click.echo(_scores_line("mean", run.metrics["mean"]))
    if run.folds.value == "all" and run.status.value == "done":
        click.echo(f"  trained on: {', '.join(trained_on(run))}; no frame held out. Score it elsewhere: "
                   f"`flask egonet predict {run.checkpoints[0].id} --activity NAME`, then `flask egonet score`.")
    if run.status.value != "done":
        raise click.ClickException(run.message or f"run {run.id} {run.status.value}")


def _scores_line(name: str, scores: dict) -> str:
    def f(key):
        return f"{scores[key]:.3f}" if scores.get(key) is not None else "-"

    return f"  {name:<14} MF {f('max_f')}  AP {f('ap')}   (action-object prior: MF {f('aop_max_f')}  AP {f('aop_ap')})"


@bp.cli.command("train-depth")
@click.option("--epochs", type=click.IntRange(min=1), default=10, show_default=True)
@click.option("--size", default="160x120", show_default=True, callback=_size, help="Training size WIDTHxHEIGHT.")
@click.option("--lr", type=click.FloatRange(min=0, min_open=True), default=1e-3, show_default=True, help="Adam's learning rate.")
@click.option("--batch-size", type=click.IntRange(min=1), default=4, show_default=True)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--activities", "activities", multiple=True, help="Train on these activities only (repeat the option; default: all).")
@click.option("--name", help="Name of the run.")
@click.option("--queue", is_flag=True, help="Queue the run for `flask egonet worker` instead of training here.")
def train_depth_command(epochs, size, lr, batch_size, seed, device, activities, name, queue):
    """Train a monocular depth network on every frame with measured depth.

    A training run (model depth-lite) with its epochs; the last 20% of each
    activity's frames are held out and scored (AbsRel, delta<1.25) against a
    constant depth. `flask egonet predict-depth` then uses it.
    """
    from app.services.training import execute_run
    from app.services.training.depth import DepthRequest, create_depth_run, start_depth_run

    request = DepthRequest(epochs=epochs, width=size[0], height=size[1], lr=lr, batch_size=batch_size, seed=seed,
                           device=device, activity_ids=_activity_ids(activities), name=name)
    if queue:
        run = start_depth_run(request)
        click.echo(f"run {run.id} queued: start `flask egonet worker` to train it")
        return
    run = create_depth_run(request)
    bar = TrainingBar()
    try:
        run = execute_run(run.id, on_progress=bar)
    finally:
        bar.close()
    click.echo(f"run {run.id} ({run.name}): {run.status.value}")
    m = run.metrics.get("depth")
    if m:
        click.echo(f"held-out ({m['test_frames']} frames): AbsRel {_number(m['abs_rel'])} delta<1.25 {_number(m['delta1'])}; "
                   f"median-scaled {_number(m['abs_rel_median_scaled'])} / {_number(m['delta1_median_scaled'])}; "
                   f"constant {m['constant_depth_m']:.2f} m: {_number(m['constant_abs_rel'])} / {_number(m['constant_delta1'])}")
    if run.status.value != "done":
        raise click.ClickException(run.message or f"run {run.id} {run.status.value}")


def _number(value) -> str:
    return "-" if value is None else f"{value:.3f}"


@bp.cli.command("predict-depth")
@click.option("--activity", required=True, help="The activity whose frames without depth get predicted depth and DHG.")
@click.option("--checkpoint", "checkpoint_id", type=int, metavar="ID", help="A depth run's checkpoint [default: the newest].")
@click.option("--device", type=click.Choice(["cpu", "cuda"]), default="cpu", show_default=True)
def predict_depth_command(activity, checkpoint_id, device):
    """Predict depth, and DHG from it, for every frame of an activity that has no depth.

    Marked predicted wherever shown or used; measured depth is never replaced.
    Frames without intrinsics get an assumed camera (60 degrees wide), and say so.
    """
    from app.services.training.depth import predict_depth

    report = predict_depth(activity, checkpoint_id=checkpoint_id, device=device)
    click.echo(f"checkpoint {report.checkpoint_id}: {report.predicted} frames given predicted depth and DHG"
               f" ({report.assumed_intrinsics} with assumed intrinsics); kept {report.kept_measured} with measured depth"
               f" and {report.kept_dhg} with imported DHG")


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


@bp.cli.command("activations")
@click.argument("checkpoint_id", type=int, metavar="CHECKPOINT")
@click.argument("frame_id", type=int, metavar="FRAME")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), help="The PNG [default: activations-<checkpoint>-<frame>.png].")
def activations_command(checkpoint_id, frame_id, out):
    """Draw the paper's Figure 3 for checkpoint CHECKPOINT on frame FRAME (the id in the frame page's address).

    Each pathway's fc7 (RGB, DHG; for egonet-lite the last feature map of
    each stream), averaged over channels and upsampled to the frame, over
    its input, with a colour bar. The frame page shows it afterwards.
    """
    from app.extensions import db
    from app.models import Frame
    from app.models.training import Checkpoint
    from app.services.activations import figure_path

    checkpoint = db.session.get(Checkpoint, checkpoint_id)
    if checkpoint is None:
        raise click.BadParameter(f"no checkpoint with id {checkpoint_id}", param_hint="CHECKPOINT")
    frame = db.session.get(Frame, frame_id)
    if frame is None:
        raise click.BadParameter(f"no frame with id {frame_id}", param_hint="FRAME")
    out = out or Path(f"activations-{checkpoint_id}-{frame_id}.png")
    from egonet.io import write_atomic

    write_atomic(out, figure_path(checkpoint, frame, in_request=False).read_bytes())
    click.echo(f"{out}: checkpoint {checkpoint.id} ({checkpoint.run.model_name}) on frame {frame.id}")


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


def _csv_list(ctx, param, value: str | None):
    if value is None:
        return None
    items = [v.strip() for v in value.split(",") if v.strip()]
    if param.name == "seeds":
        try:
            return tuple(int(v) for v in items)
        except ValueError:
            raise click.BadParameter(f"give seeds as integers separated by commas, e.g. 0,1,2 (got {value!r})") from None
    return tuple(items)


@bp.cli.command("ablations")
@click.option("--models", callback=_csv_list, help="Comma-separated variants [default: the paper's six: "
              "egonet, single-stream, egonet-rgb, egonet-dhg, no-coords, no-embedding].")
@click.option("--seeds", callback=_csv_list, default="0,1,2", show_default=True, help="Comma-separated seeds, one run per model and seed.")
@click.option("--folds", type=click.Choice(["loao", "single"]), default="loao", show_default=True)
@click.option("--epochs", type=click.IntRange(min=1), default=10, show_default=True)
@click.option("--size", default="320x240", show_default=True, callback=_size, help="Training size WIDTHxHEIGHT.")
@click.option("--batch-size", type=click.IntRange(min=1), default=4, show_default=True)
@click.option("--lr", type=click.FloatRange(min=0, min_open=True), help="Learning rate for the mean loss [default: per model, or the paper's with --init].")
@click.option("--init", "init", type=click.Path(dir_okay=False), metavar="FILE", help="ImageNet VGG16 .pth or DeepLab .caffemodel for every run.")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--activities", "activities", multiple=True, help="Only these activities (repeatable; default: all).")
@click.option("--name", help="Name of the set [default: ablations <date time>].")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              help="Folder for ablations.md/.csv/.json [default: instance/ablations/<name>].")
@click.option("--queue", is_flag=True, help="Queue the runs for the worker; write the table later with --table NAME.")
@click.option("--table", "table_only", metavar="NAME", help="Only write the table (n per activity, 95% intervals) of an existing set's finished runs.")
def ablations_command(models, seeds, folds, epochs, size, batch_size, lr, init, device, activities, name, out_dir, queue, table_only):
    """Train every paper variant under one split, seeds and budget, and write one table beside the paper's.

    Each model and seed is a training run like `flask egonet train` makes
    (same engine, recorded, on the Training and Scores pages). The table
    gives MF / AP per activity, pooled over its n held-out frames (n in each
    column's title), their mean over activities with the standard deviation
    over seeds and a 95% BCa bootstrap interval over frames (1000 resamples,
    seed 0, the same resamples for every seed), the paper's numbers beside,
    and the code version.
    """
    from flask import current_app

    from app.models import utcnow
    from app.services.training import RunRequest, execute_run
    from app.services.training import ablations

    if table_only:
        _write_ablation_table(table_only, out_dir)
        return
    name = (name or "").strip() or f"ablations {utcnow():%Y-%m-%d %H:%M:%S}"
    base = RunRequest(
        folds=folds, epochs=epochs, device=device, width=size[0], height=size[1], lr=lr, batch_size=batch_size,
        init=init, activity_ids=_activity_ids(activities),
    )
    plan = ablations.AblationPlan(name=name, models=models or ablations.DEFAULT_MODELS, seeds=seeds, base=base)
    runs = ablations.create_ablations(plan)
    click.echo(f"ablation set {name!r}: {len(runs)} runs ({', '.join(plan.models)} x seeds {', '.join(map(str, plan.seeds))})")
    if queue:
        for run in runs:
            enqueue("train_run", run.id)
        click.echo(f"runs {runs[0].id}-{runs[-1].id} queued; then: flask egonet ablations --table {name!r}")
        return
    for index, run in enumerate(runs, 1):
        click.echo(f"[{index}/{len(runs)}] run {run.id}: {run.name}")
        bar = TrainingBar()
        try:
            execute_run(run.id, on_progress=bar)
        except Exception as exc:  # noqa: BLE001 - the run records its failure; the others still train
            click.echo(f"  run {run.id} failed: {exc}", err=True)
        finally:
            bar.close()
    _write_ablation_table(name, out_dir or Path(current_app.instance_path) / "ablations" / _slug(name))


def _write_ablation_table(name: str, out_dir: Path | None) -> None:
    from flask import current_app

    from app.services.training import ablations

    table = ablations.ablation_table(name)
    paths = ablations.write_table(table, out_dir or Path(current_app.instance_path) / "ablations" / _slug(name))
    click.echo(ablations.table_markdown(table))
    click.echo(f"written: {', '.join(str(p) for p in paths)}")


def _activity_ids(activities) -> tuple[int, ...] | None:
    from app.extensions import db
    from app.models import Activity

    if not activities:
        return None
    found = dict(db.session.execute(db.select(Activity.name, Activity.id).where(Activity.name.in_(activities))).all())
    missing = [a for a in activities if a not in found]
    if missing:
        raise click.ClickException(f"no activity named {', '.join(map(repr, missing))}")
    return tuple(found[a] for a in activities)


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", name).strip("-") or "set"
