"""An admin queues a run on the Training page and watches its progress; the viewer shows a heatmap."""

import numpy as np
import pytest
from sqlalchemy import update

from app.extensions import db
from app.models import Frame
from app.models.training import Checkpoint, Prediction, RunStatus, TrainingRun
from app.services import media
from app.services.demo import create_demo
from egonet import io
from tests.browser.conftest import screenshot, sign_in

pytestmark = pytest.mark.browser


def test_queue_a_run_watch_it_and_see_a_heatmap(live_app, live_server, page, monkeypatch):
    monkeypatch.setattr("app.tasks.train_run", lambda run_id: None)  # no worker here: the test plays it
    with live_app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, seed=1, width=160, height=120)
    sign_in(page, live_app, live_server)

    page.goto(live_server + "/training/")
    page.get_by_text("Start a run").click()
    page.fill("input[name=name]", "browser run")
    page.fill("input[name=epochs]", "2")
    page.get_by_label("cooking").check()
    page.get_by_label("dining").check()
    screenshot(page, "training-form")
    page.get_by_role("button", name="Queue the run").click()
    page.wait_for_load_state("networkidle")
    row = page.locator("#runs tr[data-run]").first
    assert "browser run" in row.inner_text() and row.locator("[data-field=status]").text_content() == "queued"

    # The worker's reports reach the row without a reload.
    with live_app.app_context():
        run = db.session.execute(db.select(TrainingRun)).scalar_one()
        db.session.execute(
            update(TrainingRun).where(TrainingRun.id == run.id).values(
                status=RunStatus.RUNNING, progress=0.42, loss=0.1234, eta_s=125.0, message="fold 1/2 (cooking): epoch 1/2"
            )
        )
        db.session.commit()
        run_id = run.id
    page.wait_for_function("() => document.querySelector('#runs [data-field=percent]').textContent === '42%'")
    assert row.locator("[data-field=loss]").inner_text() == "0.1234"
    assert row.locator("[data-field=eta]").inner_text() == "2 min 05 s"
    screenshot(page, "training-progress")

    # It finishes: the page reloads and shows the checkpoint; the viewer shows the heatmap.
    with live_app.app_context():
        frame = db.session.execute(db.select(Frame).order_by(Frame.id)).scalars().first()
        checkpoint = Checkpoint(run_id=run_id, fold="cooking", path=f"run-{run_id}/cooking.pt", epochs=2,
                                metrics={"max_f": 0.61, "ap": 0.52, "aop_max_f": 0.41, "aop_ap": 0.3}, test_frame_ids=[frame.id])
        yy, xx = np.mgrid[: frame.height, : frame.width]
        blob = np.exp(-((xx - frame.width / 2) ** 2 + (yy - frame.height * 0.7) ** 2) / (2 * 20.0**2))
        path = media.store(io.encode_png(np.round(blob * 65535).astype(np.uint16)), ".png")
        db.session.add_all([checkpoint, Prediction(run_id=run_id, checkpoint=checkpoint, frame_id=frame.id, path=path, held_out=True)])
        db.session.execute(
            update(TrainingRun).where(TrainingRun.id == run_id).values(
                status=RunStatus.DONE, progress=1.0, message="done",
                metrics={"folds": {}, "mean": {"max_f": 0.61, "ap": 0.52, "aop_max_f": 0.41, "aop_ap": 0.3}},
            )
        )
        db.session.commit()
        frame_id = frame.id
    page.wait_for_function("() => document.querySelector('#checkpoints') !== null")
    assert page.locator("#runs [data-field=status]").first.text_content() == "done"
    assert "0.610" in page.locator("#runs").inner_text()
    screenshot(page, "training-done")

    page.goto(f"{live_server}/training/runs/{run_id}")
    assert page.locator(".pred-tile img").nth(1).evaluate("img => img.complete && img.naturalWidth > 0")
    screenshot(page, "training-detail")

    page.goto(f"{live_server}/frames/{frame_id}")
    overlay = page.locator("#view-prediction")
    assert not overlay.is_visible()
    page.get_by_label("prediction heatmap").check()
    assert overlay.is_visible() and overlay.evaluate("img => img.complete && img.naturalWidth > 0")
    screenshot(page, "training-viewer-heatmap")


def test_charts_follow_a_run_compare_runs_browse_frames_and_delete(live_app, live_server, page):
    """The run page's charts update as epochs arrive; runs are compared, renamed, browsed frame by frame, deleted."""
    from app.services import training
    from app.services.training.history import record_epochs

    page.set_viewport_size({"width": 1280, "height": 800})
    with live_app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, seed=2, width=160, height=120)
        frames = db.session.execute(db.select(Frame).order_by(Frame.id)).scalars().all()
        ids = {}
        for name, status, folds, epochs in (("lite 10 epochs", RunStatus.DONE, ("cooking", "dining"), 6),
                                            ("lite live", RunStatus.RUNNING, ("single",), 2)):
            run = TrainingRun(name=name, model_name="egonet-lite", folds="loao", epochs=6, device="cpu", seed=0,
                              config={"train": {"width": 160, "height": 120, "lr": 0.02, "lr_power": 0.9, "momentum": 0.9,
                                                "weight_decay": 5e-4, "batch_size": 4}, "activities": list(folds), "frames": 4},
                              status=status, progress=0.3)
            db.session.add(run)
            db.session.flush()
            for i, fold in enumerate(folds):
                record_epochs(run.id, fold, [{"epoch": e, "train_loss": 0.7 / e + 0.05 * i, "loss": 0.6 / e + 0.1, "lr": 0.02,
                                              "max_f": min(0.9, 0.2 + 0.1 * e - 0.05 * i)} for e in range(1, epochs + 1)])
                if status is RunStatus.DONE:
                    checkpoint = Checkpoint(run=run, fold=fold, path=f"run-{run.id}/{fold}.pt", epochs=epochs,
                                            metrics={"max_f": 0.75, "aop_max_f": 0.45 + 0.05 * i, "threshold": 0.4},
                                            test_frame_ids=[f.id for f in frames[2 * i : 2 * i + 2]])
                    db.session.add(checkpoint)
                    for k, frame in enumerate(frames[2 * i : 2 * i + 2]):
                        yy, xx = np.mgrid[: frame.height, : frame.width]
                        blob = np.exp(-((xx - frame.width * (0.3 + 0.4 * k)) ** 2 + (yy - frame.height * 0.6) ** 2) / (2 * 18.0**2))
                        path = media.store(io.encode_probability_png(blob.astype(np.float32)), ".png")
                        db.session.add(Prediction(run=run, checkpoint=checkpoint, frame_id=frame.id, path=path, held_out=True,
                                                  f_score=0.2 + 0.5 * k - 0.1 * i, precision=0.5, recall=0.6))
            ids[name] = run.id
        db.session.commit()
    done, live = ids["lite 10 epochs"], ids["lite live"]
    sign_in(page, live_app, live_server)

    # The live run's charts grow as the worker records epochs, without a reload.
    page.goto(f"{live_server}/training/runs/{live}")
    page.wait_for_function("() => document.querySelector('#run-chart').dataset.loaded === '2'")
    assert page.locator("#chart-mf path.line").count() == 1 and page.locator("#chart-loss path.line").count() == 2
    with live_app.app_context():
        record_epochs(live, "single", [{"epoch": 3, "train_loss": 0.2, "loss": 0.3, "lr": 0.01, "max_f": 0.55}])
        db.session.commit()
    page.wait_for_function("() => document.querySelector('#run-chart').dataset.loaded === '3'")
    assert page.locator("#chart-mf circle.dot").count() == 3
    screenshot(page, "training-run-chart")

    # Two runs on one chart; the fold choice lists the folds of both.
    page.goto(f"{live_server}/training/")
    page.wait_for_function("() => document.querySelector('#compare').dataset.loaded === '15'")
    assert page.locator("#chart-compare path.line").count() == 2
    assert page.locator("#compare-fold option").all_inner_texts() == ["mean over folds", "single", "cooking", "dining"]
    page.select_option("#compare-fold", "dining")
    assert page.locator("#chart-compare path.line").count() == 1
    page.select_option("#compare-metric", "train_loss")
    page.select_option("#compare-fold", "__mean__")
    page.locator(f"input.compare-run[value='{live}']").uncheck()
    page.wait_for_function("() => document.querySelectorAll('#chart-compare path.line').length === 1")
    assert f"compare={done}" in page.url
    page.locator(f"input.compare-run[value='{live}']").check()
    page.wait_for_function("() => document.querySelectorAll('#chart-compare path.line').length === 2")
    screenshot(page, "training-compare")

    # Rename and tag the finished run; browse its frames worst first; delete it after the confirmation.
    page.goto(f"{live_server}/training/runs/{done}")
    page.get_by_text("Rename or tag").click()
    page.fill("#edit-run input[name=name]", "lite baseline")
    page.fill("#edit-run input[name=tags]", "baseline, cpu")
    page.get_by_role("button", name="Save").click()
    assert "saved" in page.locator(".flash").inner_text() and "lite baseline" in page.locator("h1").inner_text()
    page.get_by_role("link", name="Per-frame results (worst first)").click()
    page.wait_for_url(f"**/training/runs/{done}/frames")  # loaded: all_inner_texts reads what is there, without waiting
    scores = page.locator("#frame-rows [data-field=f]").all_inner_texts()
    assert scores == sorted(scores) and len(scores) == 4
    first = page.locator("#frame-rows img").first
    first.wait_for()
    page.wait_for_function("() => [...document.querySelectorAll('#frame-rows img')].every(i => i.complete && i.naturalWidth > 0)")
    screenshot(page, "training-frames")
    page.goto(f"{live_server}/training/runs/{done}")
    page.get_by_role("link", name="Delete…").click()
    assert "2 checkpoints" in page.locator("#delete-plan").inner_text()
    page.get_by_role("button", name=f"Delete run {done}").click()
    assert "deleted" in page.locator(".flash").inner_text()
    assert page.locator(f"#runs tr[data-run='{done}']").count() == 0
    with live_app.app_context():
        assert db.session.get(TrainingRun, done) is None
        assert training.checkpoints() == []
