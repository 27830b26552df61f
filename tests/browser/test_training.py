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
    live_app.config["CHECKPOINT_ROOT"] = str(media.Path(live_app.config["MEDIA_ROOT"]).parent / "checkpoints")
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
    page.wait_for_function("() => document.querySelector('#runs [data-field=percent]').textContent === '42%'", timeout=10_000)
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
    page.wait_for_function("() => document.querySelector('#checkpoints') !== null", timeout=10_000)
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
