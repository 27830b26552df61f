"""Hostile imports: decompression bombs, zip traversal, links, zip bombs."""

import stat
import struct
import zipfile
import zlib

import numpy as np
import pytest

from app.extensions import db
from app.models import Frame
from app.services.importing import FrameItem, add_frames, import_path
from egonet import io
from tests.app.factories import image_folder


def png_claiming(width: int, height: int) -> bytes:
    """A tiny PNG whose header claims a huge image (the pixels are never there)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\x00" * 64)) + chunk(b"IEND", b"")


def test_decompression_bomb_is_refused_before_decoding(tmp_path):
    path = tmp_path / "bomb.png"
    path.write_bytes(png_claiming(100_000, 100_000))
    with pytest.raises(io.MediaError, match=r"bomb.png: image .*is larger than the limit"):
        io.read_image(path)
    path.write_bytes(png_claiming(9000, 9000))  # under Pillow's own limit, over ours
    with pytest.raises(io.MediaError, match=r"image of 9000x9000 pixels is larger than the limit"):
        io.read_image(path)
    with pytest.raises(io.MediaError, match="larger than the limit"):
        io.decode_mask(path.read_bytes())


def test_zip_of_a_recording_imports(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=3, depth=True)
    archive = tmp_path / "take2.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        for p in folder.rglob("*"):
            if p.is_file():
                zf.write(p, f"rec/{p.relative_to(folder)}")
    report = import_path(archive, activity="cooking")
    assert (report.added, report.sequence) == (3, "take2")
    assert all(f.depth_path for f in db.session.execute(db.select(Frame)).scalars())


def nothing_imported():
    return db.session.execute(db.select(Frame)).first() is None


@pytest.mark.parametrize("name", ["../evil.png", "/etc/evil.png", "rgb/../../evil.png", "C:/evil.png"])
def test_zip_path_traversal_is_refused(ctx, tmp_path, name):
    archive = tmp_path / "bad.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        zf.writestr("rgb/00000.png", io.encode_png(__import__("numpy").zeros((4, 4, 3), "uint8")))
        zf.writestr(name, b"x")
    with pytest.raises(io.MediaError, match="unsafe path"):
        import_path(archive, activity="cooking")
    assert nothing_imported()
    assert not (tmp_path.parent / "evil.png").exists()


def test_zip_links_and_bombs_are_refused(ctx, tmp_path):
    archive = tmp_path / "link.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        info = zipfile.ZipInfo("rgb/00000.png")
        info.external_attr = (stat.S_IFLNK | 0o777) << 16
        zf.writestr(info, "/etc/passwd")
    with pytest.raises(io.MediaError, match="is a link"):
        import_path(archive, activity="cooking")

    bomb = tmp_path / "bomb.zip"
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("rgb/00000.png", b"\x00" * (50 * 1024**2))
    with pytest.raises(io.MediaError, match="inflates"):
        import_path(bomb, activity="cooking")

    (tmp_path / "broken.zip").write_bytes(b"PK not really")
    with pytest.raises(io.MediaError, match="not a readable zip"):
        import_path(tmp_path / "broken.zip", activity="cooking")
    assert nothing_imported()


def lie_about_size(archive, name: str, size: int) -> None:
    """Make both of the zip's headers for member ``name`` claim ``size`` bytes."""
    with zipfile.ZipFile(archive) as zf:
        local = zf.getinfo(name).header_offset
    data = bytearray(archive.read_bytes())
    struct.pack_into("<I", data, local + 22, size)
    entry = data.find(b"PK\x01\x02")
    while entry != -1:
        (length,) = struct.unpack_from("<H", data, entry + 28)
        if data[entry + 46 : entry + 46 + length] == name.encode():
            struct.pack_into("<I", data, entry + 24, size)
        entry = data.find(b"PK\x01\x02", entry + 1)
    archive.write_bytes(bytes(data))


def test_zip_member_larger_than_its_header_is_refused(ctx, tmp_path):
    archive = tmp_path / "liar.zip"
    png = io.encode_png(np.random.default_rng(0).integers(0, 255, (40, 40, 3), dtype=np.uint8))
    with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("rgb/00000.png", png)
    lie_about_size(archive, "rgb/00000.png", 100)
    with pytest.raises(io.MediaError, match=r"'rgb/00000.png' does not match its header"):
        import_path(archive, activity="cooking")
    assert nothing_imported()


def test_frames_over_the_side_limit_are_refused_naming_the_file(app, runner, tmp_path):
    app.config["MAX_FRAME_SIDE"] = 60
    wide = image_folder(tmp_path / "wide", n=2, size=(48, 64))  # 64 px wide
    result = runner.invoke(args=["egonet", "import", str(wide), "--activity", "cooking"])
    assert result.exit_code != 0, result.output
    (error,) = [line for line in result.output.splitlines() if line.startswith("Error: ")]  # after the progress bar's
    assert error.endswith("00000.png: image of 64x48 pixels is larger than the limit of 60 pixels a side (MAX_FRAME_SIDE)")
    with app.app_context():
        # An array, as the demo and videos give their frames.
        item = FrameItem("rendered", 0, "demo kitchen 0", rgb=np.zeros((61, 10, 3), np.uint8))
        with pytest.raises(io.MediaError, match=r"demo kitchen 0: image of 10x61 pixels"):
            add_frames(activity="kitchen", sequence="demo", items=[item])
        assert nothing_imported()
        app.config["MAX_FRAME_SIDE"] = 64
        assert import_path(wide, activity="cooking").added == 2
