import os
import time

from app.services import media
from app.services.importing import import_path
from tests.app.factories import image_folder


def test_media_check_finds_orphans_and_missing_files(ctx, runner, tmp_path):
    import_path(image_folder(tmp_path / "rec", n=2, depth=True), activity="cooking")
    result = runner.invoke(args=["egonet", "media-check"])
    assert result.exit_code == 0 and "4 files, 4 referenced, 0 missing, 0 orphaned" in result.output

    orphan = media.store(b"written before a crash", ".png")
    old = time.time() - 7200
    os.utime(media.local_path(orphan), (old, old))
    fresh = media.store(b"in flight right now", ".png")
    report = media.check(remove_orphans=True, grace_s=3600)
    assert set(report.orphans) == {orphan, fresh} and report.removed == [orphan]
    assert not media.local_path(orphan).exists() and media.local_path(fresh).exists()

    victim = sorted(media.referenced_paths())[0]
    media.local_path(victim).unlink()
    result = runner.invoke(args=["egonet", "media-check"])
    assert result.exit_code == 1 and f"missing: {victim}" in result.output
