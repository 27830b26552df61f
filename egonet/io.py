"""Reading and writing the media of a frame: RGB, depth, DHG, masks, intrinsics.

Every reader takes a path and returns an array; every failure raises
``MediaError`` whose message names the file and the reason, so an import can
stop with a one-line explanation.

Conventions:
    * RGB images are uint8 (H, W, 3) in RGB order.
    * Depth is float32 (H, W) metres along the optical axis, 0 where missing.
      On disk: 16-bit PNG in millimetres, or ``.npy`` / ``.npz`` in metres.
    * DHG images are uint8 (H, W, 3) in the authors' file order: gray,
      height, depth (``egonet.dhg.GRAY``, ``HEIGHT``, ``DEPTH``).
    * Masks are bool (H, W). On disk: a PNG whose pixels are 0 or one other
      value (0/1 or 0/255).
    * Intrinsics are the 3x3 camera matrix K (float64).
"""

import io as _io
import json
import os
import re
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import cv2
import numpy as np
from PIL import Image, UnidentifiedImageError

from egonet.errors import EgonetError

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov")
DEPTH_SUFFIXES = (".png", ".npy", ".npz")

# JSON from users (request bodies, definition files, imports) nests at most
# this deep; deeper is refused before the decoder, which would recurse.
MAX_JSON_DEPTH = 100
_DEPTH_STEP = np.zeros(256, np.int8)
_DEPTH_STEP[list(b"[{")] = 1
_DEPTH_STEP[list(b"]}")] = -1
_SCAN_CHUNK = 2**20
# Text no database column holds: NUL (PostgreSQL refuses it) and UTF-16 surrogates, which in a Python
# string are unpaired ones (not Unicode, so not UTF-8). The project's one rule for text from outside:
# decode_json refuses them in every string and key, app.validation in every other string a request carries.
UNSAFE_TEXT = re.compile("[\x00\ud800-\udfff]")
# Where a JSON text can hold such a string: a raw surrogate, or an escaped NUL or surrogate (a raw NUL is
# already refused by json.loads). A cheap linear look that decides whether the decoded value is walked.
_MAYBE_UNSAFE_JSON = re.compile(r"[\ud800-\udfff]|\\u(?:0000|[dD][89a-fA-F])")

# Images larger than this are refused before they are decoded, so a small
# file that claims a huge size (a decompression bomb) costs nothing.
MAX_PIXELS = 64_000_000


class MediaError(EgonetError):
    """A media file that cannot be used; the file is the field, named in the message."""

    def __init__(self, path: str | Path, reason: str):
        super().__init__(f"{path}: {reason}", field=str(path), reason=reason)
        self.path = str(path)


def write_atomic(path: str | Path, data: bytes | Callable[[BinaryIO], None], *, durable: bool = False) -> None:
    """Write a file through a temporary file in the same folder and a rename.

    Readers see the old file or the new one, never half of one; a failure
    leaves no temporary file behind. This is the project's one atomic writer
    (media, caches, checkpoints).

    Args:
        path: The file to (re)place; its folder is created.
        data: The bytes, or a function that writes into the open binary file
            (e.g. ``lambda fh: torch.save(state, fh)``, so a large object is
            never held twice in memory).
        durable: Also flush the data to disk before the rename (for files a
            committed database row will point at).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=path.suffix)
    try:
        with os.fdopen(fd, "wb") as fh:
            if callable(data):
                data(fh)
            else:
                fh.write(data)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def check_rgb(image: object, name: str, *, min_side: int = 1) -> tuple[int, int]:
    """Check that ``image`` is a uint8 (H, W, 3) array with sides >= ``min_side``; return (H, W).

    Raises:
        ValueError: naming ``name`` and what was given instead.
    """
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        desc = f"{image.dtype} {image.shape}" if isinstance(image, np.ndarray) else type(image).__name__
        raise EgonetError(f"{name} must be a uint8 (H, W, 3) RGB array, got {desc}", field=name)
    h, w = image.shape[:2]
    if h < min_side or w < min_side:
        raise EgonetError(f"{name} must be at least {min_side}x{min_side} pixels, got {w}x{h}", field=name)
    return h, w


def image_size(data: bytes, *, path: str | Path = "<bytes>") -> tuple[int, int]:
    """(width, height) from an encoded image's header, without decoding it.

    Raises:
        MediaError: not an image, or more than ``MAX_PIXELS`` pixels.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # we apply our own limit below
            with Image.open(_io.BytesIO(data)) as probe:
                width, height = probe.size
    except Image.DecompressionBombError:
        raise MediaError(path, f"image is larger than the limit of {MAX_PIXELS} pixels") from None
    except (UnidentifiedImageError, OSError, ValueError):
        raise MediaError(path, "not a readable image (corrupt or unknown format)") from None
    if width * height > MAX_PIXELS:
        raise MediaError(path, f"image of {width}x{height} pixels is larger than the limit of {MAX_PIXELS} pixels")
    return width, height


def decode_image(data: bytes, *, path: str | Path = "<bytes>") -> np.ndarray:
    """Decode encoded image bytes (JPEG or PNG) into RGB uint8 (H, W, 3)."""
    image_size(data, path=path)
    buf = np.frombuffer(data, np.uint8)
    image = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if buf.size else None
    if image is None:
        raise MediaError(path, "not a readable image (corrupt or unknown format)")
    if image.dtype != np.uint8:
        raise MediaError(path, f"expected an 8-bit image, got {image.dtype}")
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    elif image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    else:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(image)


def read_image(path: str | Path) -> np.ndarray:
    """Read a JPEG or PNG file as RGB uint8 (H, W, 3)."""
    path = Path(path)
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        raise MediaError(path, f"unknown image format {path.suffix!r} (use {', '.join(IMAGE_SUFFIXES)})")
    return decode_image(read_bytes(path), path=path)


def encode_png(image: np.ndarray) -> bytes:
    """Encode an RGB or RGBA uint8 (H, W, 3 or 4), a gray uint8/uint16 (H, W) or a bool (H, W) array as PNG bytes."""
    if image.dtype == bool:
        image = image.astype(np.uint8) * 255
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGBA2BGRA if image.shape[2] == 4 else cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise EgonetError("image: could not encode as PNG", field="image")
    return buf.tobytes()


def encode_probability_png(probability: np.ndarray) -> bytes:
    """Encode a map of probabilities (H, W) in [0, 1] as a 16-bit gray PNG
    (value x 65535: steps of 1.5e-5, far finer than any threshold used).

    Example:
        >>> p = np.array([[0.0, 0.5], [0.25, 1.0]])
        >>> bool(np.abs(decode_probability_png(encode_probability_png(p)) - p).max() <= 1 / 65535)
        True
    """
    scaled = np.round(np.clip(np.asarray(probability, np.float64), 0.0, 1.0) * 65535.0)
    return encode_png(scaled.astype(np.uint16))


def decode_probability_png(data: bytes, *, path: str | Path = "probability") -> np.ndarray:
    """A map written by ``encode_probability_png``, as float32 (H, W) in [0, 1].

    Raises:
        MediaError: not a single-channel 16-bit PNG.
    """
    raw = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.dtype != np.uint16 or raw.ndim != 2:
        raise MediaError(path, "must be a single-channel 16-bit PNG (probability x 65535)")
    return raw.astype(np.float32) / 65535.0


def read_depth(path: str | Path) -> np.ndarray:
    """Read a depth map as float32 metres (H, W), 0 where missing.

    16-bit PNGs hold millimetres; ``.npy`` and ``.npz`` (the ``depth`` array,
    or the only one) hold metres. NaN and negative values become 0.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".png":
        data = read_bytes(path)
        image_size(data, path=path)
        raw = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if raw is None:
            raise MediaError(path, "not a readable PNG (corrupt?)")
        if raw.dtype != np.uint16 or raw.ndim != 2:
            raise MediaError(path, f"depth PNG must be single-channel 16-bit millimetres, got {raw.dtype} {raw.shape}")
        return raw.astype(np.float32) / 1000.0
    if suffix in (".npy", ".npz"):
        try:
            loaded = np.load(path, allow_pickle=False)
        except Exception as exc:  # numpy raises many kinds for bad files
            raise MediaError(path, f"not a readable numpy file ({exc})") from None
        if isinstance(loaded, np.lib.npyio.NpzFile):
            with loaded:
                keys = list(loaded.keys())
                if "depth" in keys:
                    depth = loaded["depth"]
                elif len(keys) == 1:
                    depth = loaded[keys[0]]
                else:
                    raise MediaError(path, f"npz holds {keys}; name the depth array 'depth'")
        else:
            depth = loaded
        if depth.ndim != 2 or depth.dtype.kind not in "fiu":
            raise MediaError(path, f"depth must be a 2-D numeric array in metres, got {depth.dtype} {depth.shape}")
        depth = depth.astype(np.float32)
        depth[~np.isfinite(depth) | (depth < 0)] = 0.0
        return depth
    raise MediaError(path, f"unknown depth format {path.suffix!r} (use {', '.join(DEPTH_SUFFIXES)})")


def encode_depth_png(depth_m: np.ndarray) -> bytes:
    """Encode depth in metres as a 16-bit PNG in millimetres (0 = missing)."""
    depth = np.nan_to_num(np.asarray(depth_m, np.float64), nan=0.0)
    mm = np.clip(np.round(depth * 1000.0), 0, 65535).astype(np.uint16)
    return encode_png(mm)


def read_dhg(path: str | Path) -> np.ndarray:
    """Read a DHG image as uint8 (H, W, 3) in (gray, height, depth) channel order.

    The file stores the channels in that order as an ordinary RGB image (the
    authors' DHG JPEGs and ours alike), so it is read as RGB, unchanged:
    ``egonet.dhg.decode_dhg`` turns it into depth and height.
    """
    data = read_bytes(Path(path))
    image_size(data, path=path)
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise MediaError(path, "not a readable image (corrupt or unknown format)")
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise MediaError(path, f"DHG must be a 3-channel 8-bit image, got {image.dtype} {image.shape}")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def read_mask(path: str | Path) -> np.ndarray:
    """Read a binary mask PNG as bool (H, W); pixels are 0 or one other value."""
    path = Path(path)
    return decode_mask(read_bytes(path), path=path)


def decode_mask(data: bytes, *, path: str | Path = "<bytes>") -> np.ndarray:
    """Decode binary mask PNG bytes into bool (H, W)."""
    image_size(data, path=path)
    raw = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if raw is None:
        raise MediaError(path, "not a readable PNG (corrupt?)")
    if raw.ndim == 3:
        if not (raw == raw[..., :1]).all():
            raise MediaError(path, "mask must be grayscale (0 and one other value)")
        raw = raw[..., 0]
    if raw.dtype == np.uint8:  # bincount is ~10x faster than unique on large masks
        values = np.flatnonzero(np.bincount(raw.ravel(), minlength=256))
    else:
        values = np.unique(raw)
    if len(values) > 2 or (len(values) == 2 and values[0] != 0):
        raise MediaError(path, f"mask must be binary (0 and one other value), found values {values[:6].tolist()}")
    return raw > 0


def parse_intrinsics(data: object, *, path: str | Path = "<json>") -> np.ndarray:
    """Parse camera intrinsics from decoded JSON into a 3x3 matrix K.

    Accepted forms:
        * ``{"fx": .., "fy": .., "cx": .., "cy": ..}``
        * ``{"K": [[..], [..], [..]]}`` or a bare 3x3 nested list
        * ``{"intrinsic_matrix": [9 numbers]}`` (Open3D's column-major form) or
          a flat list of 9 numbers in row-major or column-major order (told
          apart by where the principal point sits).
    """
    try:
        if isinstance(data, dict) and {"fx", "fy", "cx", "cy"} <= data.keys():
            fx, fy, cx, cy = (float(data[k]) for k in ("fx", "fy", "cx", "cy"))
            K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], np.float64)
        else:
            if isinstance(data, dict):
                for key in ("K", "intrinsic_matrix", "camera_matrix", "intrinsics"):
                    if key in data:
                        data = data[key]
                        break
                else:
                    raise MediaError(path, "intrinsics JSON needs fx, fy, cx, cy or a 3x3 matrix 'K'")
            K = np.asarray(data, np.float64)
            if K.shape == (9,):
                # Column-major puts cx, cy at 6, 7 and zeros at 2, 5.
                K = K.reshape(3, 3).T if (K[2] == 0 and K[5] == 0 and K[6] != 0) else K.reshape(3, 3)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, MediaError):
            raise
        raise MediaError(path, f"intrinsics are not numbers ({exc})") from None
    if K.shape != (3, 3):
        raise MediaError(path, f"intrinsics must be a 3x3 matrix, got shape {K.shape}")
    if not np.isfinite(K).all() or K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]):
        raise MediaError(path, "intrinsics must have fx, fy > 0 and a last row of 0 0 1")
    return K


UNSAFE_REASON = "holds a NUL character or an unpaired surrogate"


class UnsafeText(ValueError):
    """A string holding NUL or an unpaired surrogate (``UNSAFE_TEXT``); ``field`` says where (``a[2].b``;
    ``body`` when the document is that string)."""

    def __init__(self, field: str):
        super().__init__(f"{field or 'the document'}: {UNSAFE_REASON}")
        self.field = field or "body"


def _unsafe_path(value: object, path: str = "") -> str | None:
    """Where in a decoded JSON value (nested at most ``MAX_JSON_DEPTH``) a key or string is unsafe text."""
    if isinstance(value, str):
        return path if UNSAFE_TEXT.search(value) else None
    if isinstance(value, dict):
        for key, item in value.items():
            where = f"{path}.{key}" if path else key
            if UNSAFE_TEXT.search(key):
                return path or "(a key)"
            if (found := _unsafe_path(item, where)) is not None:
                return found
    elif isinstance(value, list):
        for i, item in enumerate(value):
            if (found := _unsafe_path(item, f"{path}[{i}]")) is not None:
                return found
    return None


def json_depth(data: bytes, *, limit: int | None = None) -> int:
    """How deep the brackets of a JSON text (UTF-8 bytes) nest outside its strings, in one linear pass.

    A quote opens or closes a string unless an odd run of backslashes precedes it; brackets inside
    strings are text. Vectorised a mebibyte at a time (backslash runs from a running maximum, string
    state from a running count of quotes), with the state carried from one piece to the next. For
    valid JSON this is the nesting of its arrays and objects; in an invalid text it is exact up to the
    first error, where ``json.loads`` stops. With ``limit``, the scan stops at the first piece that
    goes deeper.
    """
    buf = np.frombuffer(data, np.uint8)
    run, inside, depth, deepest = 0, False, 0, 0
    for start in range(0, buf.size, _SCAN_CHUNK):
        piece = buf[start:start + _SCAN_CHUNK]
        index = np.arange(piece.size, dtype=np.int64)
        # The last position at or before each one that is not a backslash (-1: none in this piece).
        last_plain = np.maximum.accumulate(np.where(piece == ord("\\"), -1, index))
        before = np.concatenate(([-1], last_plain[:-1]))
        backslashes = index - 1 - before + np.where(before < 0, run, 0)
        quotes = np.cumsum((piece == ord('"')) & (backslashes % 2 == 0), dtype=np.int64)
        outside = (quotes % 2 == 1) == inside  # XOR with the state at the piece's start
        running = depth + np.cumsum(_DEPTH_STEP[piece] * outside, dtype=np.int64)
        deepest = max(deepest, int(running.max()))
        run = run + piece.size if last_plain[-1] < 0 else piece.size - 1 - int(last_plain[-1])
        inside ^= bool(quotes[-1] % 2)
        depth = int(running[-1])
        if limit is not None and deepest > limit:
            break
    return deepest


def decode_json(data: bytes | str) -> object:
    """Decode a JSON document from outside (a request body, a file): the project's one JSON reader for
    what users send, so no document costs more than a linear scan however deep it nests.

    Raises:
        ValueError: not JSON (a ``json.JSONDecodeError``, or a ``UnicodeDecodeError`` for bytes that are
            not UTF-8/16/32), or nested deeper than ``MAX_JSON_DEPTH``; ``UnsafeText`` (a ValueError)
            when a string or key holds ``UNSAFE_TEXT``.

    Example:
        >>> decode_json(b'{"clicks": [[1, 2]]}')
        {'clicks': [[1, 2]]}
    """
    if isinstance(data, bytes | bytearray):
        encoding = json.detect_encoding(data)
        text = data.decode(encoding, "surrogatepass")
        utf8 = data if encoding.startswith("utf-8") else text.encode("utf-8", "surrogatepass")
    else:
        text, utf8 = data, data.encode("utf-8", "surrogatepass")
    # Deeper than the limit is refused before json.loads, which would recurse.
    if json_depth(utf8, limit=MAX_JSON_DEPTH) > MAX_JSON_DEPTH:
        raise ValueError(f"nested deeper than {MAX_JSON_DEPTH} levels")
    value = json.loads(text)
    if _MAYBE_UNSAFE_JSON.search(text) and (where := _unsafe_path(value)) is not None:
        raise UnsafeText(where)
    return value


def read_intrinsics(path: str | Path) -> np.ndarray:
    """Read a JSON intrinsics file (see ``parse_intrinsics``) into K (3, 3)."""
    path = Path(path)
    try:
        data = decode_json(read_bytes(path))
    except ValueError as exc:
        raise MediaError(path, f"not valid JSON ({exc})") from None
    return parse_intrinsics(data, path=path)


def read_bytes(path: str | Path) -> bytes:
    """Read a file's bytes; a failure raises MediaError naming the file."""
    path = Path(path)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise MediaError(path, f"cannot read ({exc.strerror or exc})") from None
