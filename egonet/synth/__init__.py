"""Deterministic synthetic first-person RGB-D frames with action-object masks.

Used by ``flask egonet demo`` to fill a fresh installation with data that
behaves like the paper's dataset: seven activities, RGB, metric depth, height
above the floor and a per-pixel action-object mask for every frame.

Each frame is a small 3D scene (room, furniture, objects, the wearer's hands
and forearms) built from analytic primitives (boxes, vertical cylinders and
ellipsoids, each with its own pose) and ray-cast per pixel with numpy. The
scene is sampled from generators seeded with ``(seed, activity, index)``, so
:func:`render_frame` is a pure function of its arguments and any frame can be
rendered alone. The scene, and so the ground truth, does not depend on the
resolution (only on the aspect ratio, which sets the vertical field of view).

Activities differ in layout, posture and mix (share of tactile frames in
brackets): cooking, a counter at ~0.9 m with a hob, pots and pans, standing
(~75 %); dining, a table at ~0.75 m with plates and cups, seated (~70 %);
grocery, tall shelving packed with products, standing and looking forward
(~65 %); hotel, a dresser with a TV and lamp, a bed and luggage, standing or
seated (~45 %, visual action-objects are more common); desk work, a desk with
monitor, laptop, keyboard and papers, seated (~70 %); shopping, a display
table with clothes, shoes and bags, wall shelves and a clothes rack, standing
(~60 %); dishwashing, a counter with a sink, steep look-down (~80 %).

World frame: x to the wearer's right, y forward, z up, floor at ``z = 0``; the
wearer stands (or sits) near the origin facing +y. Camera frame: OpenCV (x
right, y down, z forward). ``depth_m`` is the z coordinate in the camera frame;
pixel ``(u, v)`` looks along ``K^-1 [u, v, 1]`` (pixel centres at integer
coordinates, as in OpenCV).

Camera pose: ``pitch_deg`` > 0 looks down, ``yaw_deg`` > 0 turns right,
``roll_deg`` rotates about the optical axis. The world up direction in camera
coordinates is ``(-sin(roll) cos(pitch), -cos(roll) cos(pitch), -sin(pitch))``,
so a camera point ``X`` has height ``camera_height_m + up . X`` (this is what
``height_m`` holds; ``meta["up_cam"]`` repeats the vector).

Ground-truth rule (computed from the 3D configuration, never from pixels):

1. *Tactile*: an object is touched when the centre of a palm lies within
   ``CONTACT_M`` (6 cm) of the object's bounding box. The action-object is the
   touched object whose centre is within ``ARM_REACH_M`` (0.75 m) of the
   camera. Hands that touch nothing (resting on a table) do not count.
2. *Visual*: if no hand touches an object, the action-object is the object
   whose centre is nearest (perpendicular distance) to the gaze ray, i.e. the
   optical axis, among objects in front of the camera whose centres are within
   ``VISUAL_RANGE_M`` (1.5 m) of it.
3. The mask is that object's visible pixels: hands, forearms and other objects
   in front of it occlude it.

Scenes are constructed so the rule has one clear answer (a single touched
object; for visual frames no other object within ``VISUAL_RANGE_M`` lies
within 5 cm of the action-object's distance to the ray) and the mask covers at
least about 0.5 % of the image (checked at 128 pixels wide with a margin).
A configuration that fails is resampled deterministically (the attempt number
is part of the seed). Distractors include objects of the action-object's kind,
often with the same colour, placed out of reach or off the gaze ray, so the
ground truth needs the 3D cues (distance, height, contact with a hand).

Modules: :mod:`~egonet.synth.scene` (primitives, materials, the scene and
small geometry helpers), :mod:`~egonet.synth.objects` (object kinds and
placing them on surfaces), :mod:`~egonet.synth.layouts` (rooms and furniture
per activity), :mod:`~egonet.synth.sampling` (the action-object, gaze, hands
and distractors), :mod:`~egonet.synth.truth` (the ground-truth rule),
:mod:`~egonet.synth.raycast` (ray casting), :mod:`~egonet.synth.shading`
(textures, lighting, noise) and :mod:`~egonet.synth.render` (the entry points).

Example:
    >>> frame = render_frame("cooking", 3, seed=0, width=160, height=120)
    >>> frame.rgb.shape, frame.depth_m.dtype, bool(frame.mask.any())
    ((120, 160, 3), dtype('float32'), True)
"""

from egonet.synth.layouts import ACTIVITIES
from egonet.synth.render import HFOV_DEG, SynthFrame, intrinsics, render_activity, render_frame
from egonet.synth.truth import ARM_REACH_M, CONTACT_M, VISUAL_RANGE_M

__all__ = [
    "ACTIVITIES",
    "ARM_REACH_M",
    "CONTACT_M",
    "HFOV_DEG",
    "VISUAL_RANGE_M",
    "SynthFrame",
    "intrinsics",
    "render_activity",
    "render_frame",
]
