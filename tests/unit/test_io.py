import json

import cv2
import numpy as np
import pytest

from egonet import io
from tests.realdata import EGONET_SAMPLES


def test_intrinsics_forms_agree(tmp_path):
    K = np.array([[500.0, 0, 320.0], [0, 510.0, 240.0], [0, 0, 1]])
    forms = [
        {"fx": 500, "fy": 510, "cx": 320, "cy": 240},
        {"K": K.tolist()},
        K.tolist(),
        K.ravel().tolist(),  # row-major flat
        {"intrinsic_matrix": K.T.ravel().tolist(), "width": 640, "height": 480},  # Open3D column-major
    ]
    for i, form in enumerate(forms):
        path = tmp_path / f"k{i}.json"
        path.write_text(json.dumps(form))
        np.testing.assert_array_equal(io.read_intrinsics(path), K)


@pytest.mark.parametrize(
    "content, reason",
    [
        ("{not json", "not valid JSON"),
        ("[" * 50_000 + "]" * 50_000, "nested deeper than 100 levels"),
        ('{"fx": 1}', "needs fx, fy, cx, cy"),
        ("[[1, 0], [0, 1]]", "3x3"),
        ('{"fx": -5, "fy": 5, "cx": 1, "cy": 1}', "fx, fy > 0"),
        ('{"fx": "a", "fy": 5, "cx": 1, "cy": 1}', "not numbers"),
    ],
)
def test_bad_intrinsics_name_the_file(tmp_path, content, reason):
    path = tmp_path / "camera.json"
    path.write_text(content)
    with pytest.raises(io.MediaError, match=reason) as info:
        io.read_intrinsics(path)
    assert str(path) in str(info.value)


def test_depth_png_is_millimetres_and_npy_metres(tmp_path):
    depth = np.array([[0.0, 0.5], [1.234, 2.0]], np.float32)
    (tmp_path / "d.png").write_bytes(io.encode_depth_png(depth))
    np.testing.assert_allclose(io.read_depth(tmp_path / "d.png"), depth, atol=5e-4)
    np.save(tmp_path / "d.npy", np.where(depth == 0, np.nan, depth))
    np.testing.assert_array_equal(io.read_depth(tmp_path / "d.npy"), depth)
    np.savez(tmp_path / "d.npz", depth=depth, other=depth)
    np.testing.assert_array_equal(io.read_depth(tmp_path / "d.npz"), depth)


def test_eight_bit_depth_png_is_refused(tmp_path):
    (tmp_path / "d.png").write_bytes(io.encode_png(np.zeros((4, 4), np.uint8)))
    with pytest.raises(io.MediaError, match="16-bit"):
        io.read_depth(tmp_path / "d.png")


def test_image_round_trip_and_corrupt(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 255, (6, 8, 3), dtype=np.uint8)
    (tmp_path / "a.png").write_bytes(io.encode_png(rgb))
    np.testing.assert_array_equal(io.read_image(tmp_path / "a.png"), rgb)
    (tmp_path / "b.jpg").write_bytes(b"\xff\xd8\xff\xe0 garbage")
    with pytest.raises(io.MediaError, match="b.jpg"):
        io.read_image(tmp_path / "b.jpg")
    with pytest.raises(io.MediaError, match="unknown image format"):
        io.read_image(tmp_path / "c.gif")


def test_masks_must_be_binary(tmp_path):
    mask = np.zeros((5, 5), bool)
    mask[1:3, 2:4] = True
    (tmp_path / "m.png").write_bytes(io.encode_png(mask))
    np.testing.assert_array_equal(io.read_mask(tmp_path / "m.png"), mask)
    (tmp_path / "g.png").write_bytes(io.encode_png(np.arange(25, dtype=np.uint8).reshape(5, 5)))
    with pytest.raises(io.MediaError, match="binary"):
        io.read_mask(tmp_path / "g.png")


def test_rgba_png_round_trip(tmp_path):
    rgba = np.random.default_rng(0).integers(0, 256, (5, 7, 4), dtype=np.uint8)
    path = tmp_path / "layer.png"
    path.write_bytes(io.encode_png(rgba))
    back = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), cv2.COLOR_BGRA2RGBA)
    assert np.array_equal(back, rgba)


def test_write_atomic_writes_bytes_or_through_a_function_and_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "sub" / "a.bin"
    io.write_atomic(target, b"first")
    io.write_atomic(target, lambda fh: fh.write(b"second"), durable=True)
    assert target.read_bytes() == b"second"

    def fail(fh):
        fh.write(b"half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        io.write_atomic(target, fail)
    assert target.read_bytes() == b"second"
    assert sorted(p.name for p in target.parent.iterdir()) == ["a.bin"]


def test_dhg_is_read_in_the_authors_file_order(tmp_path):
    """A DHG file is an RGB image whose channels are gray, height, depth; read_dhg keeps that order."""
    from egonet.dhg import DEPTH, GRAY, HEIGHT

    image = np.zeros((8, 10, 3), np.uint8)
    image[..., GRAY], image[..., HEIGHT], image[..., DEPTH] = 11, 22, 33
    path = tmp_path / "dhg.png"
    # As any image program writes an RGB file (OpenCV's own order is BGR).
    cv2.imwrite(str(path), image[..., ::-1])
    read = io.read_dhg(path)
    assert read[0, 0].tolist() == [11, 22, 33]
    with pytest.raises(io.MediaError, match="3-channel"):
        cv2.imwrite(str(tmp_path / "gray.png"), image[..., 0])
        io.read_dhg(tmp_path / "gray.png")


@pytest.mark.skipif(not EGONET_SAMPLES.exists(), reason="shared data not present")
def test_authors_dhg_files_decode_gray_from_channel_0():
    from egonet.dhg import decode_dhg

    for path in sorted((EGONET_SAMPLES / "dhg").glob("*.jpg")):
        decoded = decode_dhg(io.read_dhg(path))
        gray = cv2.cvtColor(io.read_image(EGONET_SAMPLES / "rgb" / path.name), cv2.COLOR_RGB2GRAY)
        assert np.corrcoef(decoded.gray.ravel(), gray.ravel())[0, 1] > 0.95
        # Depth is not the frame's brightness (the old order decoded the gray channel as depth).
        assert abs(np.corrcoef(np.nan_to_num(decoded.depth).ravel(), gray.ravel())[0, 1]) < 0.5
