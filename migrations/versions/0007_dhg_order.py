"""dhg order: stored DHG images rewritten into the authors' channel order (gray, height, depth)

Revision ID: 0007
Revises: 0009

Before this revision our DHG images (computed from depth, or the demo's) were
stored depth, height, gray, the reverse of the authors' files, while the
authors' own DHG files were imported as they are (gray first). This revision
gives every stored DHG image the authors' order: an image whose last channel
is the frame's gray (our old order) is reversed, written as a new
content-addressed PNG and the frame points at it; one whose first channel is
the gray already (an imported authors' file) is left alone. Which channel is
the gray is told by its correlation with the frame's own gray image (our
gray channel is the frame's gray exactly; the authors' correlates 0.97-0.99).
An image whose frame cannot be read, or whose end channels are both flat,
came from our code: it is reversed either way (so a downgrade undoes it).

The old files stay in the media folder as orphans (another row may share
their bytes); ``flask egonet media-check --remove-orphans`` removes them
after an hour. Downgrading gives every DHG image the old order the same way.
Offline (``--sql``) there is no media folder to rewrite: the revision says so
and changes nothing.
"""

import logging

import cv2
import numpy as np
import sqlalchemy as sa
from alembic import context, op

revision = "0007"
down_revision = "0009"
branch_labels = None
depends_on = None

log = logging.getLogger("alembic.runtime.migration")

GRAY_FIRST, GRAY_LAST = "gray-height-depth", "depth-height-gray"
SAMPLE_SIDE = 160  # the correlation is measured on copies at most this wide


def upgrade():
    _rewrite(to=GRAY_FIRST)


def downgrade():
    _rewrite(to=GRAY_LAST)


def _rewrite(*, to: str) -> None:
    if context.is_offline_mode():
        log.warning("0007: offline mode cannot rewrite DHG media; run `flask db upgrade` against the database")
        return
    from app.services import media  # the one module that touches the site's files, folder or bucket
    from egonet import io

    frame = sa.table("frame", sa.column("id", sa.Integer()), sa.column("rgb_path", sa.String()),
                     sa.column("dhg_path", sa.String()))
    conn = op.get_bind()
    rows = conn.execute(sa.select(frame.c.rgb_path, frame.c.dhg_path).where(frame.c.dhg_path.is_not(None))).all()
    rgb_of: dict[str, str] = {}
    for rgb_path, dhg_path in rows:
        rgb_of.setdefault(dhg_path, rgb_path)
    rewritten = 0
    for i, (dhg_path, rgb_path) in enumerate(rgb_of.items(), start=1):
        new_path = _reordered(media, dhg_path, rgb_path, to=to, io=io)
        if new_path is not None:
            conn.execute(frame.update().where(frame.c.dhg_path == dhg_path).values(dhg_path=new_path))
            rewritten += 1
        if i % 500 == 0:
            log.info("0007: %d of %d DHG images checked", i, len(rgb_of))
    log.info("0007: %d of %d DHG images rewritten into the %s order", rewritten, len(rgb_of), to)


def _reordered(media, dhg_path: str, rgb_path: str, *, to: str, io) -> str | None:
    """The media path of the image in order ``to`` (written when new), or None when it is in that order already."""
    try:
        dhg = io.read_dhg(media.local_path(dhg_path))
    except (ValueError, FileNotFoundError) as exc:  # a missing or broken file: media-check reports it, nothing to rewrite
        log.warning("0007: DHG %s left as it is: %s", dhg_path, exc)
        return None
    if _order(dhg, _frame_gray(media, rgb_path, io)) == to:
        return None
    return media.store(io.encode_png(np.ascontiguousarray(dhg[..., ::-1])), ".png")


def _frame_gray(media, rgb_path: str, io) -> np.ndarray | None:
    try:
        return cv2.cvtColor(io.read_image(media.local_path(rgb_path)), cv2.COLOR_RGB2GRAY)
    except (ValueError, FileNotFoundError):
        return None


def _order(dhg: np.ndarray, gray: np.ndarray | None) -> str | None:
    """Which end of ``dhg`` holds the frame's gray; None when it cannot be told."""
    if gray is None or gray.shape != dhg.shape[:2]:
        return None
    scale = min(1.0, SAMPLE_SIDE / max(gray.shape))
    size = (max(1, round(gray.shape[1] * scale)), max(1, round(gray.shape[0] * scale)))
    small_gray = cv2.resize(gray, size, interpolation=cv2.INTER_AREA).astype(np.float64).ravel()
    small = cv2.resize(dhg, size, interpolation=cv2.INTER_AREA).astype(np.float64).reshape(-1, 3)
    first, last = (_correlation(small[:, c], small_gray) for c in (0, 2))
    if first == last:  # both flat, or the same channel twice
        return None
    return GRAY_FIRST if first > last else GRAY_LAST


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    norm = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / norm) if norm > 0 else -np.inf
