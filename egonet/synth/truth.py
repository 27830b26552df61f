"""The ground-truth rule: which object is the action-object.

Computed from the 3D configuration, never from pixels: the touched object
within reach, else the object nearest the gaze ray (see :mod:`egonet.synth`).
"""

from __future__ import annotations

import numpy as np

from egonet.synth.scene import _point_box_distance, _ray_distance, _Scene

ARM_REACH_M = 0.75
"""A touched object counts as tactile within this distance (camera to centre)."""
CONTACT_M = 0.06
"""A palm touches an object when its centre is this close to the object's box."""
VISUAL_RANGE_M = 1.5
"""Visual action-objects are at most this far from the camera (centre)."""

_VISUAL_MARGIN = 0.05  # other objects are at least this much further from the gaze ray


def _resolve_ground_truth(scene: _Scene) -> tuple[str, int] | None:
    """Apply the ground-truth rule of :mod:`egonet.synth` to the 3D configuration.

    Returns ``(kind, object id)``, or None when the rule has no single answer.
    """
    touched = []
    for i, o in enumerate(scene.objects):
        if np.linalg.norm(o.centre - scene.eye) > ARM_REACH_M:
            continue
        gap = min((_point_box_distance(h.palm, o.lo, o.hi) for h in scene.hands), default=np.inf)
        if gap <= CONTACT_M:
            touched.append(i)
    if len(touched) == 1:
        return ("tactile", touched[0])
    if touched:
        return None
    # Hands that touch something out of reach do not make a frame tactile, but
    # they do make it ambiguous; the builder never produces them.
    for o in scene.objects:
        if min((_point_box_distance(h.palm, o.lo, o.hi) for h in scene.hands), default=np.inf) <= CONTACT_M:
            return None
    gaze = scene.R[:, 2]
    ranked = []
    for i, o in enumerate(scene.objects):
        v = o.centre - scene.eye
        if np.linalg.norm(v) <= VISUAL_RANGE_M and np.dot(v, gaze) > 0:
            ranked.append((_ray_distance(scene.eye, gaze, o.centre), i))
    if not ranked:
        return None
    ranked.sort()
    if len(ranked) > 1 and ranked[1][0] - ranked[0][0] < _VISUAL_MARGIN * 0.5:
        return None
    return ("visual", ranked[0][1])
