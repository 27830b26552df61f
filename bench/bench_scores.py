"""Time of the Scores page's report on the demo, with 1,000 bootstrap resamples, against a per-resample loop.

Builds the demo (``flask egonet demo``: 40 frames per activity, a quarter
left unlabelled, 320x240) in a temporary instance, adds three runs of
egonet-lite identical but for the seed and a fourth trained longer (their
held-out maps: the truth blurred, plus noise of their own), and a study of
20 frames per activity answered by 5 participants (two of whom stop early
and whose sessions then end: their last trials are unanswered). The cache
is filled once; then, medians of ``--repeats`` runs:

* ``build_report`` as the page calls it (pooled, shared frames, 1,000
  resamples, BCa intervals), and under the other conventions and frames;
* ``GET /scores/`` through the test client (the report, the plots, the
  template);
* the naive reference: for each row and activity, 1,000 times, draw the
  frames, sum their counts (numpy), reduce with ``Score.from_counts``, then
  take the percentile interval (no jackknife: less than ours computes).

CPU time is ``time.process_time`` (all threads of the process); the ratio is
naive CPU / ours CPU. The machine is shared: the load average is printed
before and after.

Run: ``.venv/bin/python bench/bench_scores.py [--frames-per-activity 40] [--repeats 5]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from datetime import timedelta
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flask_migrate import upgrade  # noqa: E402

from app import create_app  # noqa: E402
from app.extensions import db  # noqa: E402
from app.models import Activity, utcnow  # noqa: E402
from app.models.training import Checkpoint, FoldsMode, Prediction, RunStatus, TrainingRun  # noqa: E402
from app.services import ground_truth, media, scoring, studies  # noqa: E402
from app.services.demo import create_demo  # noqa: E402
from app.services.users import create_user  # noqa: E402
from egonet import io  # noqa: E402
from egonet.metrics import Counts, Score  # noqa: E402

PASSWORD = "bench-password-8842!"


def timed(fn, repeats: int) -> tuple[float, float, object]:
    """Median CPU and wall seconds of ``fn`` over ``repeats`` runs, and its last result."""
    cpu, wall, result = [], [], None
    for _ in range(repeats):
        c, w = time.process_time(), time.perf_counter()
        result = fn()
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - w)
    return statistics.median(cpu), statistics.median(wall), result


def add_run(name: str, seed: int, epochs: int) -> None:
    """A finished leave-one-activity-out run whose held-out maps are the truth blurred plus its own noise."""
    rng = np.random.default_rng(seed)
    train = {"model": "egonet-lite", "folds": "loao", "epochs": epochs, "seed": seed, "device": "cpu", "lr": 0.02, "batch_size": 4}
    run = TrainingRun(name=name, model_name="egonet-lite", folds=FoldsMode.LOAO, epochs=epochs, device="cpu", seed=seed,
                      status=RunStatus.DONE, config={"train": train, "activity_ids": None, "frames": 0})  # fmt: skip
    db.session.add(run)
    db.session.flush()
    checkpoint = Checkpoint(run_id=run.id, fold="all", path=f"run-{run.id}/all.pt", epochs=epochs)
    db.session.add(checkpoint)
    db.session.flush()
    frames = ground_truth.labelled_frames()
    truths = ground_truth.ground_truths([f.id for f in frames])
    for frame in frames:
        mask = ground_truth.mask_of(truths[frame.id]).astype(np.float32)
        prob = np.clip(cv2.GaussianBlur(mask, (0, 0), 6.0) * (0.5 + 0.1 * epochs / 6) + 0.45 * rng.random(mask.shape), 0, 1)
        path = media.store(io.encode_probability_png(prob.astype(np.float32)), ".png")
        db.session.add(Prediction(run_id=run.id, checkpoint_id=checkpoint.id, frame_id=frame.id, path=path, held_out=True))
    db.session.commit()


def add_study(per_activity: int) -> None:
    """Five participants click near each frame's object; P04 and P05 stop after half their trials."""
    rng = np.random.default_rng(3)
    activity_ids = list(db.session.execute(db.select(Activity.id)).scalars())
    study = studies.create_study(name="bench study", activity_ids=activity_ids, frames_per_activity=per_activity, seed=1, sigma_px=15.0)
    for person in studies.add_participants(study, count=5):
        studies.answer_consent(person, agree=True)
        studies.start_session(person)
        state = studies.session_state(person)
        answered = 0
        limit = None if person.number <= 3 else len(study.frames) // 2
        while state.trial is not None and (limit is None or answered < limit):
            mask = ground_truth.mask_of(ground_truth.ground_truths([state.trial.frame.id])[state.trial.frame.id])
            ys, xs = np.nonzero(mask)
            if ys.size:
                answer = studies.Answer(clicks=[(float(xs.mean() + rng.normal(0, 8)), float(ys.mean() + rng.normal(0, 8)), 600.0)])
            else:
                answer = studies.Answer(clicks=[], none=True)
            state = studies.submit(person, state.trial, answer)
            answered += 1


def naive_report(found: list[scoring.rows.Source], resamples: int, seed: int) -> dict:
    """Pooled MF and AP with percentile intervals per row and activity, and for the mean: one resample at a time."""
    rng = np.random.default_rng(seed)
    activities = sorted({a for s in found for a in s.stats.by_activity()})
    shared = {}
    for a in activities:
        having = [s.stats.by_activity()[a] for s in found if a in s.stats.by_activity()]
        shared[a] = having[0]
        for ids in having[1:]:
            shared[a] = np.intersect1d(shared[a], ids)
    draws = {a: [rng.integers(0, ids.size, ids.size) for _ in range(resamples)] for a, ids in shared.items() if ids.size}
    out = {}
    for source in found:
        per_activity = {}
        for a, picks in draws.items():
            if a not in source.stats.by_activity():
                continue
            counts = source.stats.select(shared[a])
            values = []
            for pick in picks:
                tp, fp, pos = counts.tp[pick].sum(0), counts.fp[pick].sum(0), counts.positives[pick].sum()
                score = Score.from_counts(Counts(tp, fp, pos - tp))
                values.append((score.max_f, score.ap))
            per_activity[a] = np.array(values)
            out[source.key, a] = np.quantile(per_activity[a], [0.025, 0.975], axis=0)
        if per_activity:
            out[source.key, "mean"] = np.quantile(np.mean(list(per_activity.values()), axis=0), [0.025, 0.975], axis=0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames-per-activity", type=int, default=40)
    parser.add_argument("--study-frames", type=int, default=20, help="frames per activity in the study")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--resamples", type=int, default=1000)
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    with tempfile.TemporaryDirectory() as tmp:
        app = create_app({"TESTING": True, "SECRET_KEY": "bench", "SQLALCHEMY_DATABASE_URI": f"sqlite:///{tmp}/bench.sqlite3",
                          "STORAGE_URL": tmp, "CACHE_ROOT": f"{tmp}/cache", "WTF_CSRF_ENABLED": True})  # fmt: skip
        with app.app_context():
            upgrade()
            start = time.perf_counter()
            create_demo(frames_per_activity=args.frames_per_activity)
            for seed in (0, 1, 2):
                add_run(f"lite seed {seed}", seed, epochs=6)
            add_run("lite 12 epochs", 0, epochs=12)
            add_study(min(args.study_frames, args.frames_per_activity * 3 // 4))
            create_user("admin", "admin", PASSWORD)
            print(f"set-up (demo, 4 runs, a study of 5 people): {time.perf_counter() - start:.0f} s")
            app.config["STUDY_CLOCK"] = lambda: utcnow() + timedelta(hours=2)  # the sessions are over
            start = time.perf_counter()
            report = scoring.build_report()
            print(f"first report, scoring every map into the cache: {time.perf_counter() - start:.1f} s")
            labelled = len(ground_truth.labelled_frames())
            print(f"{labelled} labelled frames; {len(report.all_rows())} rows ({len(report.rows)} top-level); "
                  f"{args.resamples} resamples")  # fmt: skip

            def page_report(**view):
                return lambda: scoring.build_report(resamples=args.resamples, **view)

            results = {}
            for label, view in (("pooled, shared frames (the page's default)", {}), ("ois-mean, shared", {"metric": "ois-mean"}),
                                ("ods-ois, shared", {"metric": "ods-ois"}), ("pooled, each row's frames", {"frames": "each"}),
                                ("pooled, with a comparison", {"compare_keys": ("run:1", "baseline:aop")})):  # fmt: skip
                results[label] = timed(page_report(**view), args.repeats)[:2]
            load_cpu, load_wall, (found, _) = timed(lambda: scoring.load_sources(), args.repeats)
            naive_cpu, naive_wall, _ = timed(lambda: naive_report(found, args.resamples, 0), 1)
        client = app.test_client()
        client.post("/login", data={"username": "admin", "password": PASSWORD, "csrf_token": _token(client)})
        page_cpu, page_wall, response = timed(lambda: client.get("/scores/"), args.repeats)
        assert response.status_code == 200, response.status_code
    print(f"\nmedians of {args.repeats} (CPU s / wall s):")
    for label, (cpu, wall) in results.items():
        print(f"  build_report, {label:<45} {cpu:6.3f} / {wall:6.3f}")
    print(f"    of which reading the cached per-frame counts              {load_cpu:6.3f} / {load_wall:6.3f}")
    print(f"  GET /scores/ (report, plots, template; {len(response.data) // 1024} KiB)         {page_cpu:6.3f} / {page_wall:6.3f}")
    cpu, _ = results["pooled, shared frames (the page's default)"]
    print(f"  naive per-resample loop (pooled MF, AP, percentile CI; 1 run) {naive_cpu:6.3f} / {naive_wall:6.3f}")
    print(f"  ratio naive / ours, bootstrap part (CPU): {naive_cpu / max(cpu - load_cpu, 1e-9):.1f}x; whole report: {naive_cpu / cpu:.1f}x")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


def _token(client) -> str:
    import re

    page = client.get("/login").get_data(as_text=True)
    return re.search(r'name="csrf-token" content="([^"]+)"', page).group(1)


if __name__ == "__main__":
    main()
