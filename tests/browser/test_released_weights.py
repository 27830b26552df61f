"""An admin imports the authors' released weights on the Training page: a refused file, then a real-size one."""

import pytest

from app.extensions import db
from app.models.training import RunStatus, TrainingRun
from tests.browser.conftest import screenshot, sign_in
from tests.caffe_files import TINY, release_layers, write_caffemodel

pytestmark = [pytest.mark.browser, pytest.mark.slow]


def test_upload_a_release_watch_it_convert(live_app, live_server, page, monkeypatch, full_rgb_caffemodel, tmp_path):
    from app.tasks import import_weights

    queued = []
    monkeypatch.setattr("app.tasks.import_weights", lambda *args: queued.append(args))  # the test plays the worker
    sign_in(page, live_app, live_server)
    page.goto(live_server + "/training/")
    page.get_by_text("Import the authors' released weights").click()

    # A file of the releases' layer names at 1/64 width: sent, checked, refused in one line.
    small = write_caffemodel(tmp_path / "small.caffemodel", release_layers(TINY["rgb+dhg"]))
    page.set_input_files("#weights-form input[name=file]", str(small))
    page.get_by_role("button", name="Upload and import").click()
    status = page.locator("#weights-status")
    status.filter(has_text="Not imported").wait_for(timeout=20_000)
    assert "layer 'conv1_1' weights have shape (1, 3, 3, 3) in the file, (64, 3, 3, 3)" in status.inner_text()
    screenshot(page, "released-weights-refused")

    # The full RGB release (270 MB, 33 chunks): the page shows the upload's progress, then the queued run.
    path, _ = full_rgb_caffemodel
    page.set_input_files("#weights-form input[name=file]", str(path))
    page.fill("#weights-form input[name=name]", "authors RGB")
    page.fill("#weights-form input[name=width]", "64")
    page.fill("#weights-form input[name=height]", "48")
    page.get_by_role("button", name="Upload and import").click()
    status.filter(has_text="queued").wait_for(timeout=120_000)
    assert "the authors' RGB release" in status.inner_text()
    page.wait_for_load_state("load")
    page.locator("#runs tr[data-run]").first.wait_for()
    row = page.locator("#runs tr[data-run]").first
    assert "authors RGB" in row.inner_text() and "released" in row.inner_text()
    screenshot(page, "released-weights-queued")

    ((run_id, upload),) = queued
    with live_app.app_context():
        import_weights.func(run_id, upload)  # what `flask egonet worker` runs
        assert db.session.get(TrainingRun, run_id).status is RunStatus.DONE
    # The poller sees it finish and the page reloads with the checkpoint.
    page.locator("#checkpoints").filter(has_text="released").wait_for(timeout=15_000)
    assert page.locator("#runs [data-field=status]").first.text_content() == "done"
    screenshot(page, "released-weights-done")
