"""The storage module on both backends: a folder and a real SeaweedFS bucket."""

import uuid

import pytest

from app.services import media
from app.services.storage import StorageUnavailable, open_store, open_url, store
from tests.app.conftest import make_app
from tests.seaweed import SeaweedFS

pytestmark = pytest.mark.both_storages


def test_keys_round_trip_list_and_delete(ctx):
    files = store()
    files.put("checkpoints/run-1/fold-1.pt", b"weights")
    files.put("checkpoints/run-1/config.json", lambda fh: fh.write(b"{}"))
    files.put("exports/one.zip", b"zip")
    assert files.get("checkpoints/run-1/fold-1.pt") == b"weights"
    assert files.local_path("checkpoints/run-1/config.json").read_bytes() == b"{}"
    assert sorted((e.key, e.size) for e in files.list("checkpoints/run-1")) == [
        ("checkpoints/run-1/config.json", 2), ("checkpoints/run-1/fold-1.pt", 7)]
    files.put("checkpoints/run-1/fold-1.pt", b"better weights")  # a changed key is read afresh
    assert files.local_path("checkpoints/run-1/fold-1.pt").read_bytes() == b"better weights"
    files.delete_prefix("checkpoints/run-1")
    assert list(files.list("checkpoints")) == [] and files.exists("exports/one.zip")
    assert not files.exists("checkpoints/run-1/fold-1.pt")
    with pytest.raises(FileNotFoundError):
        files.get("exports/none.zip")
    with pytest.raises(ValueError, match="not a storage key"):
        files.get("../secret")


def test_media_are_content_addressed_and_served(ctx, client):
    rel = media.store(b"\x89PNG not really", ".png")
    assert media.store(b"\x89PNG not really", ".png") == rel and media.read(rel) == b"\x89PNG not really"
    assert media.local_path(rel).read_bytes() == b"\x89PNG not really"
    assert [e.key for e in store().list("media")] == [f"media/{rel}"]
    assert client.get(f"/media/{rel}").status_code in (302, 401, 200)  # served to whoever may see media


def test_a_bucket_that_is_down_says_so_and_comes_back(tmp_path):
    server = SeaweedFS(tmp_path / "weed").start()
    try:
        server.create_bucket("egonet-down")
        import os
        saved = dict(os.environ)
        os.environ.update(server.environ())
        try:
            files = open_store("s3://egonet-down/p", cache=tmp_path / "cache", cache_bytes=1 << 20)
            files.put("exports/x.zip", b"x")
            server.stop()
            with pytest.raises(StorageUnavailable):
                files.get("exports/x.zip")
            server.start()
            assert files.get("exports/x.zip") == b"x"
        finally:
            os.environ.clear()
            os.environ.update(saved)
    finally:
        server.stop()


def test_storage_migrate_copies_checks_and_runs_again(ctx, runner, tmp_path, seaweedfs):
    rel = media.store(b"a frame", ".png")
    store().put("checkpoints/run-1/fold-1.pt", b"weights")
    store().put("exports/export-1.zip", b"zip")
    # From the folder to a bucket, and from a bucket to a folder.
    to = str(tmp_path / "moved") if store().url.startswith("s3://") else f"s3://egonet-test/moved-{uuid.uuid4().hex[:8]}"

    def migrate(*args):
        result = runner.invoke(args=["egonet", "storage-migrate", "--to", *args])
        return result.exit_code, result.output

    code, out = migrate(to, "--check-only")
    assert code == 1 and "3 files (0.0 MB): 0 present and equal, 3 missing or different" in out
    assert f"missing or different: media/{rel}" in out
    code, out = migrate(to)
    assert code == 0 and "3 copied, 0 there already" in out, out
    moved = open_url(to)
    assert [moved.get(k) for k in (f"media/{rel}", "checkpoints/run-1/fold-1.pt", "exports/export-1.zip")] == [
        b"a frame", b"weights", b"zip"]
    moved.put(f"media/{rel}", b"a frAme")  # damaged, the same size
    code, out = migrate(to, "--check-only")
    assert code == 1 and "2 present and equal, 1 missing or different" in out and f"different: media/{rel}" in out
    code, out = migrate(to)
    assert code == 0 and "1 copied, 2 there already" in out and moved.get(f"media/{rel}") == b"a frame"

    for args, reason in (([store().url], "is the current STORAGE_URL"), (["ftp://x/y"], "use a folder or s3://"),
                         (["s3://no-such-bucket/x"], "storage s3://no-such-bucket/x answered 404 NoSuchBucket")):
        code, out = migrate(*args)
        assert code != 0 and reason in out.strip().splitlines()[-1] and out.count("Error:") == 1, out


def test_a_buckets_copies_on_this_host_stay_within_their_budget(seaweedfs, tmp_path):
    files = open_store(f"s3://egonet-test/{uuid.uuid4().hex[:12]}", cache=tmp_path / "cache", cache_bytes=10_000)
    for i in range(30):
        files.put(f"media/{i:02d}.png", bytes([i]) * 1000)
        assert files.local_path(f"media/{i:02d}.png").read_bytes() == bytes([i]) * 1000
        copies = [p for p in (tmp_path / "cache").rglob("*") if p.is_file()]
        assert sum(p.stat().st_size for p in copies) <= 10_000
    assert sorted(p.name for p in copies)[-1] == "29.png" and len(copies) >= 9  # the most recent kept


def test_files_made_on_this_host_stay_within_their_budget(app_with):
    host = app_with(DERIVED_CACHE_BYTES=10_000)
    with host.app_context():
        made = []
        for i in range(30):
            path = media.derived(f"thumbs/{i:02d}.jpg", lambda i=i: bytes([i]) * 1000)
            assert path.read_bytes() == bytes([i]) * 1000
            media.derived("thumbs/00.jpg", lambda: pytest.fail("kept, not made again"))  # in use: kept
            made = [p for p in media.derived_path("thumbs").iterdir() if p.is_file()]
            assert sum(p.stat().st_size for p in made) <= 10_000
        assert {"00.jpg", "29.jpg"} <= {p.name for p in made} and len(made) >= 8


@pytest.mark.parametrize("gone", ["MEDIA_ROOT", "EXPORT_ROOT"])
def test_the_old_folder_settings_stop_the_app_naming_storage_url(tmp_path, gone):
    with pytest.raises(RuntimeError, match=f"{gone} is replaced by STORAGE_URL"):
        make_app("sqlite://", tmp_path, **{gone: str(tmp_path / "old")})
