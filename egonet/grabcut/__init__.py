"""Interactive GrabCut: a box, corrective strokes, undo, and a resumable state.

``GrabCutSession`` segments one object in one RGB frame the way an annotator
works: a box gives the first mask, each brush stroke ("fg" or "bg") corrects
it, ``undo`` steps back. The session is fast enough to feel interactive on
1280x960 frames and larger, on one CPU core:

* All work happens in a region of interest (ROI): the box plus a margin. The
  graph cut runs on the ROI scaled so its long side is ``work_size`` pixels
  (``cv2.grabCut`` in ``GC_EVAL`` mode, with colour models that the session
  keeps between calls, so a stroke costs one re-estimation and one cut).
* The low-resolution label is brought back to full resolution with a fast
  guided filter (He & Sun 2015): its local linear coefficients are fitted
  between the low-resolution image and label, upsampled, and applied to the
  full-resolution colours, only in a narrow band along the boundary, so the
  edge follows the image at full resolution.
* After a stroke only the part of the ROI whose low-resolution label changed is
  brought back again; the rest of the full-resolution mask is kept.
* Strokes are hard constraints: pixels under a foreground stroke are in the
  returned mask and pixels under a background stroke are out, exactly. A
  stroke changes the mask only its own way (a foreground stroke only adds
  pixels, a background stroke only removes them), and only locally: a pixel
  away from the stroke changes only if it is joined to the stroke through
  pixels that changed too, so a stroke never drops the far end of a handle.

With depth (``GrabCutSession(image, depth)``, metres, 0 or NaN where
missing) the cut models colour and depth together and prefers to cut where
depth jumps, so an object of the background's colour in front of it (a white
chair before a white wall) separates; ``cv2.grabCut`` takes colour only, so
that cut is the session's own (PyMaxflow), over the undecided pixels only.
Pixels without depth are judged by colour alone. Without depth the session
is exactly the colour-only one. The depth is the frame's, like the image:
``state()`` does not hold it, and ``from_state(image, state, depth)`` takes
it again for a session that was made with it.

Pixel conventions: points are ``(x, y)`` with ``x`` the column and ``y`` the
row, in full-resolution pixel units, and pixel ``(x, y)`` sits at integer
coordinates. A box ``(x0, y0, x1, y1)`` covers columns ``x0 <= x < x1`` and
rows ``y0 <= y < y1`` (slice convention). A stroke covers the pixels whose
distance to its polyline is at most ``radius`` (see ``stroke_footprint``).

Sessions of one frame can share a ``GrabCutFrame(image, depth)``: the
frame's checked copy and, per region of interest, the low-resolution guides
a cut needs (5-25 ms to build on a 1408x1408 frame), so a session resumed
with ``from_state`` for every request of a server, or the frame's next
object, does not build them again. With a ``GuideStore`` (named arrays in,
named arrays out) the guides go between processes too: ``share()`` saves
them, and a frame in another process loads them before building any.

Modules: :mod:`~egonet.grabcut.session` (``GrabCutSession``: box, stroke,
undo, and the loop that composes the rest), :mod:`~egonet.grabcut.frame`
(``GrabCutFrame``), :mod:`~egonet.grabcut.geometry`
(box -> ROI -> low-resolution grid), :mod:`~egonet.grabcut.colour` (the
colour models), :mod:`~egonet.grabcut.depth` (the depth checked, on the
grid, the colour-plus-depth models and depth-aware pairwise links),
:mod:`~egonet.grabcut.cut` (the graph cut at the work size: a box's first
cut, its rescue, re-cuts with strokes; with depth too),
:mod:`~egonet.grabcut.refine` (the guided filter back to full resolution),
:mod:`~egonet.grabcut.strokes` (checks and footprints),
:mod:`~egonet.grabcut.state` (undo levels and ``state()``'s format) and
:mod:`~egonet.grabcut.propagation` (``propagate``: a mask carried to the
adjacent frame by optical flow, then refined; ``carry`` says too how sure it is).

Example:
    >>> import numpy as np
    >>> image = np.zeros((120, 160, 3), np.uint8)
    >>> image[...] = (40, 120, 40)
    >>> image[40:80, 50:110] = (200, 60, 60)
    >>> session = GrabCutSession(image)
    >>> mask = session.box(40, 30, 120, 90)
    >>> bool(mask[60, 80]), bool(mask[10, 10])
    (True, False)
    >>> mask = session.stroke([(80, 60)], "bg", 3)
    >>> bool(mask[60, 80])
    False
    >>> bool(session.undo()[60, 80])
    True

    A panel of the wall's colour, 0.5 m in front of it, found by its depth:

    >>> image = np.full((120, 160, 3), 220, np.uint8)
    >>> depth = np.full((120, 160), 2.0)
    >>> depth[40:80, 50:110] = 1.5
    >>> mask = GrabCutSession(image, depth).box(40, 30, 120, 90)
    >>> bool(mask[60, 80]), bool(mask[35, 45])
    (True, False)
"""

from egonet.grabcut.frame import GrabCutFrame, GuideStore
from egonet.grabcut.propagation import Carried, carry, propagate
from egonet.grabcut.session import GrabCutSession
from egonet.grabcut.state import STATE_FORMAT
from egonet.grabcut.strokes import LABELS, stroke_footprint

__all__ = ["GrabCutSession", "GrabCutFrame", "GuideStore", "stroke_footprint", "LABELS", "STATE_FORMAT", "propagate",
           "carry", "Carried"]
