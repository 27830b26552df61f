"""The paper's ablations under one budget: every variant, the same split, seeds and settings, one table.

``plan_ablations`` turns a budget (models, seeds, folds, epochs, size...)
into one ``RunRequest`` per model and seed; ``create_ablations`` checks
and records them all as queued runs before any trains, tagged with the
set's name (``config["ablation"]``); each then trains through the same
engine as ``flask egonet train`` (``execute_run`` in the foreground, or
the worker). ``ablation_table`` scores a set's finished runs on their
held-out frames, per activity (pooled MF and AP, n frames each), with a 95 %
BCa bootstrap interval over frames for each model's mean over activities
(``egonet.metrics``: the same resamples for every seed, resampled within
each activity), and puts the paper's numbers beside them; ``write_table``
writes it as Markdown, CSV and JSON, each saying n, the interval's method,
resamples and seed, and the code version.

Every run sees the same labelled frames, so the same folds
(``egonet.train.make_folds`` is deterministic); a seed fixes the
initialisation, shuffling and augmentation alike for every model.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from app.extensions import db
from app.models import utcnow
from app.models.training import RunStatus, TrainingRun
from app.services import ground_truth
from app.services.training.control import RunRequest, TrainingProblem, create_run
from app.services.training.predictions import held_out_predictions
from app.spreadsheet import csv_text
from app.version import code_version
from egonet.io import write_atomic
from egonet.metrics import DEFAULT_RESAMPLES, Estimate, FrameCounts, Resampler, ScoreAccumulator, score_frames

#: The paper's ablations (MF, AP on its dataset; shared/docs/egonet-reference.md), in its order.
PAPER_ABLATIONS: dict[str, tuple[str, float, float]] = {
    "egonet": ("EgoNet (RGB + DHG + coordinates + embedding)", 0.396, 0.313),
    "single-stream": ("single stream on concatenated RGB+DHG+XY", 0.249, 0.166),
    "egonet-rgb": ("RGB stream only (with coordinates)", 0.363, 0.250),
    "egonet-dhg": ("DHG stream only (with coordinates)", 0.369, 0.208),
    "no-coords": ("no coordinates", 0.333, 0.232),
    "no-embedding": ("no embedding layer (fc9 removed)", 0.313, 0.202),
}
DEFAULT_MODELS: tuple[str, ...] = tuple(PAPER_ABLATIONS)
MAX_RUNS = 100
CI = "95% BCa bootstrap over held-out frames, resampled within each activity, the same resamples for every seed"


@dataclass(frozen=True)
class AblationPlan:
    """A budget shared by every variant: ``base`` gives folds, epochs, size, lr, init...; ``models`` x ``seeds`` runs."""

    name: str
    models: tuple[str, ...] = DEFAULT_MODELS
    seeds: tuple[int, ...] = (0, 1, 2)
    base: RunRequest = field(default_factory=RunRequest)


def plan_ablations(plan: AblationPlan) -> list[RunRequest]:
    """One request per model and seed, named ``"<set> · <model> · seed <s>"``.

    Raises:
        TrainingProblem: No models or seeds, a repeated one, too many runs, or a bad set name.
    """
    name = plan.name.strip()
    if not name or len(name) > 120:
        raise TrainingProblem("name the ablation set (1 to 120 characters)", field="name")
    for label, values in (("models", plan.models), ("seeds", plan.seeds)):
        if not values:
            raise TrainingProblem(f"give at least one of --{label}", field=label)
        if len(set(values)) != len(values):
            raise TrainingProblem(f"--{label} repeats a value: {', '.join(map(str, values))}", field=label)
    if len(plan.models) * len(plan.seeds) > MAX_RUNS:
        raise TrainingProblem(f"at most {MAX_RUNS} runs in one set, asked for {len(plan.models) * len(plan.seeds)}", field="seeds")
    return [
        replace(plan.base, model=model, seed=seed, name=f"{name} · {model} · seed {seed}", ablation=name)
        for model in plan.models
        for seed in plan.seeds
    ]


def create_ablations(plan: AblationPlan, *, created_by=None) -> list[TrainingRun]:
    """Check every request, then record them all as queued runs (nothing is recorded when one is bad).

    Raises:
        TrainingProblem: A bad option (naming it and the model), or a set of that name exists already.
    """
    if set_runs(plan.name.strip()):
        raise TrainingProblem(f"an ablation set named {plan.name.strip()!r} exists already: choose another --name", field="name")
    requests = plan_ablations(plan)
    runs = []
    try:
        for request in requests:
            try:
                runs.append(create_run(request, created_by=created_by))
            except TrainingProblem as exc:
                raise TrainingProblem(f"{request.model}: {exc.message}", field=exc.field) from None
    except TrainingProblem:
        for run in runs:  # all or nothing: drop the runs of this set already recorded
            db.session.delete(run)
        db.session.commit()
        raise
    return runs


def set_runs(name: str) -> list[TrainingRun]:
    """The runs of an ablation set, in the order they were planned."""
    runs = db.session.execute(db.select(TrainingRun).order_by(TrainingRun.id)).scalars()
    return [run for run in runs if (run.config or {}).get("ablation") == name]


# --------------------------------------------------------------------------- the table


Interval = tuple[float, float] | None


@dataclass
class ModelRow:
    """One variant over its seeds: per-activity and mean MF/AP with n and intervals, the seeds' spread, the paper's numbers."""

    model: str
    description: str
    paper: tuple[float, float] | None
    runs: list[int]
    per_activity: dict[str, tuple[float, float]]  # activity -> (MF, AP), mean over seeds
    mean: tuple[float, float]  # (MF, AP): mean over seeds of each run's mean over activities
    spread: tuple[float, float]  # sample standard deviation over seeds (0 with one seed)
    aop: tuple[float | None, float | None]  # the folds' action-object prior, mean over seeds
    n: dict[str, int] = field(default_factory=dict)  # activity -> held-out frames scored
    ci: tuple[Interval, Interval] = (None, None)  # 95% intervals of ``mean`` (None: the seeds' frames differ)


@dataclass
class AblationTable:
    name: str
    budget: dict
    activities: list[str]
    rows: list[ModelRow]
    notes: list[str]
    made_at: str = field(default_factory=lambda: utcnow().isoformat(timespec="seconds"))
    resamples: int = DEFAULT_RESAMPLES
    seed: int = 0  # the bootstrap's
    code_version: str = field(default_factory=code_version)


def ablation_table(name: str, *, resamples: int = DEFAULT_RESAMPLES, seed: int = 0) -> AblationTable:
    """Score a set's finished runs on their held-out frames, per activity, and group them by model.

    Args:
        name: The set's name.
        resamples: Bootstrap resamples behind each model's interval (0: none).
        seed: The bootstrap's seed.

    Raises:
        TrainingProblem: No set of that name, or none of its runs has finished.
    """
    runs = set_runs(name)
    if not runs:
        raise TrainingProblem(f"no ablation set named {name!r}", field="name", status=404)
    notes = [f"run {r.id} ({r.model_name}, seed {r.seed}) is {r.status.value}: left out" for r in runs if r.status != RunStatus.DONE]
    done = [r for r in runs if r.status == RunStatus.DONE]
    if not done:
        raise TrainingProblem(f"no run of ablation set {name!r} has finished yet", field="name", status=409)
    scored = {run.id: _counts(run) for run in done}
    for run in [r for r in done if not scored[r.id]]:  # every held-out frame lost its ground truth
        notes.append(f"run {run.id} ({run.model_name}, seed {run.seed}) has no held-out frame with a ground truth: left out")
        done.remove(run)
    if not done:
        raise TrainingProblem(f"no run of ablation set {name!r} has held-out frames to score", field="name", status=409)
    activities = sorted({a for s in scored.values() for a in s})
    resampler = Resampler(resamples=resamples, seed=seed)
    estimates = {run_id: _estimates(counts, resampler) for run_id, counts in scored.items()}
    rows = []
    for model in dict.fromkeys(r.model_name for r in done):
        mine = [r for r in done if r.model_name == model]
        rows.append(_model_row(model, mine, scored, estimates, activities))
        if rows[-1].ci[0] is None and resamples:
            notes.append(f"{model}: its seeds were scored on different frames, so its mean has no interval")
    train = done[0].config["train"]
    budget = {k: train.get(k) for k in ("folds", "epochs", "width", "height", "batch_size", "lr", "device")}
    budget |= {"seeds": sorted({r.seed for r in done}), "init": (done[0].config.get("init") or {}).get("name"),
               "frames": done[0].config.get("frames")}
    return AblationTable(name, budget, activities, rows, notes, resamples=resamples, seed=seed)


def _counts(run: TrainingRun) -> dict[str, FrameCounts]:
    """The run's held-out frames' counts per activity (frames in id order)."""
    accumulators: dict[str, ScoreAccumulator] = {}
    pairs = sorted(held_out_predictions(run), key=lambda pair: pair[0].id)
    truths = ground_truth.ground_truths([frame.id for frame, _ in pairs])
    for frame, probability in pairs:
        annotation = truths.get(frame.id)
        if annotation is None:  # no ground truth any more
            continue
        acc = accumulators.setdefault(frame.sequence.activity.name, ScoreAccumulator())
        acc.add(probability, ground_truth.mask_of(annotation), name=f"prediction of frame {frame.id}")
    return {activity: acc.frames() for activity, acc in accumulators.items()}


def _estimates(counts: dict[str, FrameCounts], resampler: Resampler) -> dict[str, dict[str, Estimate]]:
    """Pooled MF and AP per activity: on the frames, on each resample, with each jackknife group left out."""
    out = {}
    for activity, frames in counts.items():
        values = score_frames(frames, weights=resampler.weights(activity, frames.n))
        out[activity] = {statistic: resampler.estimate(v) for statistic, v in values.items()}
    return out


def _model_row(model: str, runs: list[TrainingRun], scored: dict, estimates: dict, activities: list[str]) -> ModelRow:
    per_activity = {}
    for activity in activities:
        values = [[estimates[r.id][activity][k].value for k in ("max_f", "ap")] for r in runs if activity in scored[r.id]]
        if values:
            per_activity[activity] = tuple(float(v) for v in np.mean(values, axis=0))
    # Each seed's mean over its activities (each resampled on its own), then the mean over seeds on the same resamples.
    run_means = [{k: Estimate.stratified_mean([e[k] for e in estimates[r.id].values()]) for k in ("max_f", "ap")} for r in runs]
    means = np.array([[m["max_f"].value, m["ap"].value] for m in run_means])  # (seeds, 2)
    spread = means.std(axis=0, ddof=1) if len(runs) > 1 else np.zeros(2)
    sizes = {tuple((a, f.n) for a, f in scored[r.id].items()) for r in runs}
    ci = (None, None)
    if len(sizes) == 1:
        ci = tuple(Estimate.mean([m[k] for m in run_means]).interval() for k in ("max_f", "ap"))
    aop = [(r.metrics.get("mean") or {}) for r in runs]
    aop_mean = tuple(
        float(np.mean([m[k] for m in aop])) if all(m.get(k) is not None for m in aop) else None for k in ("aop_max_f", "aop_ap")
    )
    description, *paper = PAPER_ABLATIONS.get(model, (model, None, None))
    return ModelRow(
        model=model,
        description=description,
        paper=tuple(paper) if paper[0] is not None else None,
        runs=[r.id for r in runs],
        per_activity=per_activity,
        mean=(float(means[:, 0].mean()), float(means[:, 1].mean())),
        spread=(float(spread[0]), float(spread[1])),
        aop=aop_mean,
        n={a: f.n for a, f in scored[runs[0].id].items()},
        ci=ci,
    )


# --------------------------------------------------------------------------- writing


def table_markdown(table: AblationTable) -> str:
    """The table in Markdown: MF / AP per activity with n, their mean ± the seeds' standard deviation and 95% interval, the paper's beside."""
    b = table.budget
    seeds = ", ".join(map(str, b["seeds"]))
    n = {a: max((row.n.get(a, 0) for row in table.rows), default=0) for a in table.activities}
    lines = [
        f"Ablation set {table.name!r}: {b['folds']} folds, {b['epochs']} epochs at {b['width']}x{b['height']}, "
        f"batch {b['batch_size']}, lr {_num(b['lr'], '.4g')}, seeds {seeds}, {b['frames']} labelled frames, "
        f"{'init ' + b['init'] if b['init'] else 'random initialisation'}; device {b['device']}.",
        "",
        "| model | paper MF / AP | " + " | ".join(f"{a} MF / AP (n {n[a]})" for a in table.activities)
        + " | mean MF | mean AP | AOP MF / AP | runs |",
        "|---|---|" + "---|" * len(table.activities) + "---|---|---|---|",
    ]
    for row in table.rows:
        paper = f"{row.paper[0]:.3f} / {row.paper[1]:.3f}" if row.paper else "–"
        cells = [
            f"{row.per_activity[a][0]:.3f} / {row.per_activity[a][1]:.3f}" if a in row.per_activity else "–"
            for a in table.activities
        ]
        mf, ap = (f"{m:.3f} ± {s:.3f}" + (f" [{ci[0]:.3f}, {ci[1]:.3f}]" if ci else "")
                  for m, s, ci in zip(row.mean, row.spread, row.ci, strict=True))  # fmt: skip
        aop = f"{_num(row.aop[0])} / {_num(row.aop[1])}"
        lines.append(f"| {row.model} | {paper} | " + " | ".join(cells) + f" | {mf} | {ap} | {aop} | {', '.join(map(str, row.runs))} |")
    lines += [
        "",
        "MF and AP pooled over each activity's n held-out frames. Mean: over activities, then over seeds; ± is the standard "
        f"deviation over seeds; [lo, hi] its {CI} ({table.resamples} resamples, seed {table.seed}). Code: {table.code_version}.",
    ]
    lines += [f"- {note}" for note in table.notes]
    return "\n".join(lines) + "\n"


def table_rows(table: AblationTable) -> list[dict]:
    """One flat record per model (the CSV's rows and the JSON's ``rows``)."""
    records = []
    for row in table.rows:
        (mf_lo, mf_hi), (ap_lo, ap_hi) = (ci or (None, None) for ci in row.ci)
        record = {
            "model": row.model, "description": row.description,
            "paper_max_f": row.paper[0] if row.paper else None, "paper_ap": row.paper[1] if row.paper else None,
            "mean_max_f": row.mean[0], "mean_max_f_lo": mf_lo, "mean_max_f_hi": mf_hi,
            "mean_ap": row.mean[1], "mean_ap_lo": ap_lo, "mean_ap_hi": ap_hi, "sd_max_f": row.spread[0], "sd_ap": row.spread[1],
            "seeds": len(row.runs), "aop_max_f": row.aop[0], "aop_ap": row.aop[1], "runs": " ".join(map(str, row.runs)),
        }  # fmt: skip
        for activity in table.activities:
            mf, ap = row.per_activity.get(activity, (None, None))
            record |= {f"{activity} n": row.n.get(activity, 0), f"{activity} max_f": mf, f"{activity} ap": ap}
        records.append(record | {"ci": CI, "resamples": table.resamples, "bootstrap_seed": table.seed, "code_version": table.code_version})
    return records


def write_table(table: AblationTable, out_dir: Path) -> list[Path]:
    """Write ``ablations.md``, ``ablations.csv`` and ``ablations.json`` in ``out_dir`` (atomically)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    records = table_rows(table)
    document = {"name": table.name, "made_at": table.made_at, "budget": table.budget, "activities": table.activities,
                "ci": {"method": CI, "level": 0.95, "resamples": table.resamples, "seed": table.seed},
                "code_version": table.code_version, "rows": records, "notes": table.notes}  # fmt: skip
    files = {
        "ablations.md": table_markdown(table),
        "ablations.csv": csv_text([["" if v is None else v for v in r.values()] for r in records], header=list(records[0])),
        "ablations.json": json.dumps(document, indent=2),
    }
    paths = []
    for name, text in files.items():
        write_atomic(out_dir / name, text.encode())
        paths.append(out_dir / name)
    return paths


def _num(value: float | None, spec: str = ".3f") -> str:
    return "–" if value is None or math.isnan(value) else format(value, spec)
