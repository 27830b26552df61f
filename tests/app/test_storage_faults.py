"""Storage failing under the app, with a real server (a private SeaweedFS, stopped and started again):
an import stopped half-way keeps nothing, and pages answer 503 and come back by themselves."""

import contextlib
import uuid

import pytest

from app.cli import data as cli_data
from app.extensions import db
from app.models import Activity, Frame
from app.models.exports import ExportJob
from app.services import exchange
from app.services.storage import StorageUnavailable, store
from tests.app.factories import image_folder
from tests.app.test_media_check import remove_orphans
from tests.app.test_studies_recruiting import open_study
from tests.seaweed import SeaweedFS

pytestmark = pytest.mark.one_database
BUCKET = "egonet-faults"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    server = SeaweedFS(tmp_path_factory.mktemp("weed-faults")).start()
    server.create_bucket(BUCKET)
    yield server
    server.stop()


@pytest.fixture
def on_server(server, app, app_with, tmp_path, monkeypatch):
    """An app (another host: its own cache) whose files are in the private server's bucket, which is up."""
    if server.process is None:
        server.start()
    for name, value in server.environ().items():
        monkeypatch.setenv(name, value)
    return app_with(STORAGE_URL=f"s3://{BUCKET}/{uuid.uuid4().hex[:12]}", CACHE_ROOT=str(tmp_path / "cache-s3"))


def test_storage_stopped_mid_import_keeps_nothing_and_media_check_removes_what_it_wrote(on_server, server, tmp_path,
                                                                                          monkeypatch):
    @contextlib.contextmanager
    def bar_that_stops_storage(label):
        done = []

        def on_progress(n: int) -> None:
            done.append(n)
            if len(done) == 2:
                server.stop()

        yield (lambda total: None), on_progress

    monkeypatch.setattr(cli_data, "progress_bar", bar_that_stops_storage)
    runner = on_server.test_cli_runner()
    result = runner.invoke(args=["egonet", "import", str(image_folder(tmp_path / "rec", n=4, depth=True)),
                                 "--activity", "cooking"])
    assert result.exit_code == 1
    (line,) = result.output.strip().splitlines()
    assert line.startswith(f"Error: storage s3://{BUCKET}/") and "is unreachable" in line, line
    server.start()
    with on_server.app_context():
        assert db.session.execute(db.select(Frame)).first() is None  # rolled back
        assert db.session.execute(db.select(Activity)).first() is None
        written = [entry.key for entry in store().list("media")]  # two frames' RGB and depth
        assert len(written) == 4
    assert "4 files, 0 referenced, 0 missing, 4 orphaned, 4 removed" in remove_orphans(runner, monkeypatch, orphans=4)
    with on_server.app_context():
        assert list(store().list("media")) == []


def test_pages_answer_503_while_storage_is_down_and_serve_again_when_it_is_back(on_server, server, make_user,
                                                                                 tmp_path):
    _, token = open_study(on_server, tmp_path)
    with on_server.app_context():
        frame = db.session.execute(db.select(Frame).order_by(Frame.id)).scalars().first()
        frame_id, rgb = frame.id, frame.rgb_path
    staff = on_server.test_client()
    staff.login_as(make_user("annotator", "ann"))
    staff.fetch_csrf_token()
    participant = on_server.test_client()  # the open link's example frame, before anyone is admitted
    urls = [(staff, f"/media/{rgb}"), (staff, f"/frames/{frame_id}/thumb.jpg"), (participant, f"/s/o/{token}/example")]
    box = {"frame_id": frame_id, "instance": "a", "box": [5, 5, 40, 30]}
    with on_server.app_context():
        job = ExportJob(options=exchange.ExportOptions().to_dict())
        db.session.add(job)
        db.session.commit()
        export_id = job.id
    server.stop()
    try:
        with on_server.app_context(), pytest.raises(StorageUnavailable):
            exchange.build_export(export_id)  # the worker's export fails, and its page says why in words
        page = staff.get(f"/label/exports/{export_id}").get_data(as_text=True)
        assert "file storage was unreachable; export again later" in page and BUCKET not in page
        for client, url in urls:
            with client.get(url) as response:
                page = response.get_data(as_text=True)
                assert (response.status_code, response.mimetype) == (503, "text/html"), url
                assert response.headers["Retry-After"] and "File storage is unreachable just now" in page
                for secret in (BUCKET, server.endpoint, str(server.ports["s3"]), "egonet-test"):  # egonet-test: the key
                    assert secret not in page, (url, secret)
        with staff.post("/api/label/grabcut/box", json=box) as response:
            assert response.status_code == 503 and response.get_json()["error"] == "storage_unavailable"
            assert BUCKET not in response.get_data(as_text=True)
    finally:
        server.start()
    for client, url in urls:
        with client.get(url) as response:
            assert response.status_code == 200, url
    with staff.post("/api/label/grabcut/box", json=box) as response:
        assert response.status_code == 200
