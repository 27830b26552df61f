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

Example:
    >>> frame = render_frame("cooking", 3, seed=0, width=160, height=120)
    >>> frame.rgb.shape, frame.depth_m.dtype, bool(frame.mask.any())
    ((120, 160, 3), dtype('float32'), True)
"""

from __future__ import annotations

import colorsys
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import cv2
import numpy as np

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

ACTIVITIES: tuple[str, ...] = (
    "cooking",
    "dining",
    "grocery",
    "hotel",
    "desk work",
    "shopping",
    "dishwashing",
)

HFOV_DEG = 80.0
"""Horizontal field of view of the synthetic lens (square pixels)."""
ARM_REACH_M = 0.75
"""A touched object counts as tactile within this distance (camera to centre)."""
CONTACT_M = 0.06
"""A palm touches an object when its centre is this close to the object's box."""
VISUAL_RANGE_M = 1.5
"""Visual action-objects are at most this far from the camera (centre)."""

_NEAR = 0.02  # ignore hits closer than this to the camera (m)
_CHECK_WIDTH = 128  # resolution of the visibility check (pixels wide)
_CHECK_MIN_FRACTION = 0.0065  # visible area required at the check resolution
_MAX_ATTEMPTS = 40
_IDLE_CLEARANCE = 0.12  # palms of hands that touch nothing stay this far from objects
_VISUAL_MARGIN = 0.05  # other objects are at least this much further from the gaze ray

# Primitive shapes.
_ROOM, _BOX, _CYL, _ELL = 0, 1, 2, 3
# Texture kinds.
_PLAIN, _TILES, _WOOD, _LABEL, _SCREEN, _PAPER, _FABRIC, _KEYS = range(8)

_HAND = -2  # object id of hand and arm primitives
_BACKGROUND = -1


@dataclass(frozen=True, eq=False)
class SynthFrame:
    """One rendered frame and its ground truth.

    Attributes:
        activity: One of :data:`ACTIVITIES`.
        index: Frame index within the activity.
        rgb: ``(H, W, 3)`` uint8 colour image.
        depth_m: ``(H, W)`` float32 z-depth in metres along the optical axis;
            0 where no surface is hit (the room is closed, so never in
            practice).
        height_m: ``(H, W)`` float32 height above the floor in metres; NaN
            where ``depth_m`` is 0.
        mask: ``(H, W)`` bool visible pixels of the action-object (never
            empty).
        K: ``(3, 3)`` float64 camera intrinsics.
        meta: JSON-serialisable facts about the frame: ``camera_height_m``,
            ``pitch_deg``, ``roll_deg``, ``yaw_deg``, ``up_cam``, ``kind``
            (``"tactile"`` or ``"visual"``), ``object``,
            ``object_distance_m``, ``object_height_m``, ``hands_touching``,
            ``seated``, ``n_objects``, ``same_kind_distractors``,
            ``mask_fraction``, ``hfov_deg``, ``seed``, ``attempt``.
    """

    activity: str
    index: int
    rgb: np.ndarray
    depth_m: np.ndarray
    height_m: np.ndarray
    mask: np.ndarray
    K: np.ndarray
    meta: dict


# ---------------------------------------------------------------------------
# Public entry points
# ---------------------------------------------------------------------------


def intrinsics(*, width: int, height: int) -> np.ndarray:
    """Intrinsics of the synthetic lens at a given resolution.

    Square pixels, horizontal field of view :data:`HFOV_DEG`, principal point
    at the image centre (pixel centres at integer coordinates).

    Args:
        width: Image width in pixels (> 0).
        height: Image height in pixels (> 0).

    Returns:
        ``(3, 3)`` float64 matrix ``K``.

    Example:
        >>> float(intrinsics(width=320, height=240)[0, 2])
        159.5
    """
    _check_size(width, "width")
    _check_size(height, "height")
    f = (width / 2.0) / math.tan(math.radians(HFOV_DEG) / 2.0)
    return np.array(
        [[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]],
        dtype=np.float64,
    )


def render_frame(
    activity: str, index: int, *, seed: int = 0, width: int = 320, height: int = 240
) -> SynthFrame:
    """Render one synthetic frame of an activity.

    A pure function of its arguments: the same arguments give bit-identical
    arrays, and any frame can be rendered without the ones before it.

    Args:
        activity: One of :data:`ACTIVITIES`.
        index: Frame index, 0 <= index < 2**32; each index is a different scene.
        seed: Data-set seed, 0 <= seed < 2**32.
        width: Image width in pixels (> 0).
        height: Image height in pixels (> 0).

    Returns:
        The frame with RGB, depth, height, mask, intrinsics and metadata.

    Raises:
        ValueError: If an argument is out of range or the activity unknown.

    Example:
        >>> f = render_frame("dining", 0, width=160, height=120)
        >>> f.meta["kind"] in ("tactile", "visual")
        True
    """
    act_id = _check_activity(activity)
    _check_index(index, "index")
    _check_index(seed, "seed")
    _check_size(width, "width")
    _check_size(height, "height")

    check_w = _CHECK_WIDTH
    check_h = max(8, int(round(_CHECK_WIDTH * height / width)))
    k_check = intrinsics(width=check_w, height=check_h)
    # Tactile or visual is drawn once per frame, so resampling a failed
    # configuration keeps each activity's mix.
    # Independent streams per frame: [.., 0] the kind, [.., 1, attempt] the
    # scene, [.., 2, attempt] the sensor noise. (SeedSequence pads with zeros,
    # so the stream tag must not be a trailing optional zero.)
    tactile = bool(np.random.default_rng([seed, act_id, index, 0]).random() < _ACTIVITY_SPECS[activity].tactile_prob)
    for attempt in range(_MAX_ATTEMPTS):
        rng = np.random.default_rng([seed, act_id, index, 1, attempt])
        scene = _build_scene(activity, rng, tactile=tactile)
        if scene is None:
            continue
        truth = _resolve_ground_truth(scene)
        if truth is None or truth != (scene.kind, scene.action):
            continue
        cast = _cast(scene, k_check, check_w, check_h)
        if np.mean(cast.obj == scene.action) < _CHECK_MIN_FRACTION:
            continue
        break
    else:  # pragma: no cover - construction makes this unreachable in practice
        raise RuntimeError(f"could not build a valid scene for {activity!r} frame {index}")

    K = intrinsics(width=width, height=height)
    cast = _cast(scene, K, width, height)
    noise_rng = np.random.default_rng([seed, act_id, index, 2, attempt])
    rgb = _shade(scene, cast, noise_rng)
    hit = np.isfinite(cast.t)
    depth = np.where(hit, cast.t, 0.0).astype(np.float32)
    # World z of the hit: eye height + depth * (z component of the ray with camera z = 1).
    ray_z = cast.vs[:, None] * scene.R[2, 1] + cast.us[None, :] * scene.R[2, 0] + scene.R[2, 2]
    height_m = np.where(hit, scene.eye[2] + np.where(hit, cast.t, 0.0) * ray_z, np.nan).astype(np.float32)
    mask = cast.obj == scene.action
    if not mask.any():
        # At tiny resolutions a visible object can fall between pixel centres;
        # mark the pixel nearest to its projected centre so the mask is never empty.
        mask = _fallback_mask(scene, K, width, height)
    meta = _meta(scene, activity, index, seed, attempt, mask, cast)
    return SynthFrame(
        activity=activity,
        index=index,
        rgb=rgb,
        depth_m=depth,
        height_m=height_m,
        mask=mask,
        K=K,
        meta=meta,
    )


def render_activity(
    activity: str, count: int, *, seed: int = 0, width: int = 320, height: int = 240
) -> Iterator[SynthFrame]:
    """Render frames ``0 .. count - 1`` of an activity, one at a time.

    Arguments are validated when this is called, not when iteration starts.

    Args:
        activity: One of :data:`ACTIVITIES`.
        count: Number of frames (>= 0).
        seed: Data-set seed, 0 <= seed < 2**32.
        width: Image width in pixels (> 0).
        height: Image height in pixels (> 0).

    Returns:
        An iterator of :class:`SynthFrame`, equal to calling
        :func:`render_frame` with indices ``0 .. count - 1``.

    Raises:
        ValueError: If an argument is out of range or the activity unknown.

    Example:
        >>> [f.index for f in render_activity("hotel", 2, width=64, height=48)]
        [0, 1]
    """
    _check_activity(activity)
    _check_index(count, "count")
    _check_index(seed, "seed")
    _check_size(width, "width")
    _check_size(height, "height")

    def frames() -> Iterator[SynthFrame]:
        for index in range(count):
            yield render_frame(activity, index, seed=seed, width=width, height=height)

    return frames()


# ---------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------


def _check_activity(activity: object) -> int:
    if not isinstance(activity, str) or activity not in ACTIVITIES:
        valid = ", ".join(repr(a) for a in ACTIVITIES)
        raise ValueError(f"activity must be one of {valid}; got {activity!r}")
    return ACTIVITIES.index(activity)


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _check_index(value: object, name: str) -> None:
    # Below 2**32 so each value is one word of the generator's seed.
    if not _is_int(value) or not 0 <= value < 2**32:
        raise ValueError(f"{name} must be an integer in [0, 2**32); got {value!r}")


def _check_size(value: object, name: str) -> None:
    if not _is_int(value) or value <= 0:
        raise ValueError(f"{name} must be an integer > 0 (pixels); got {value!r}")


# ---------------------------------------------------------------------------
# Scene description
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class _Mat:
    rgb: tuple[float, float, float]
    rgb2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tex: int = _PLAIN
    scale: float = 1.0
    spec: float = 0.0


@dataclass
class _Prim:
    shape: int
    centre: np.ndarray  # (3,) world
    axes: np.ndarray  # (3, 3) columns are the local axes in world coordinates
    size: np.ndarray  # (3,) half extents (box, room), radii (ellipsoid), (r, r, half height)
    material: int  # rooms use six consecutive materials, one per face
    obj: int = _BACKGROUND


@dataclass
class _Part:
    shape: int
    centre: tuple[float, float, float]  # in the object's frame (origin at the bottom centre)
    size: tuple[float, float, float]
    mat: _Mat
    axes: np.ndarray | None = None


@dataclass
class _Object:
    name: str
    colour: tuple[float, float, float]
    centre: np.ndarray  # centre of the world bounding box
    lo: np.ndarray
    hi: np.ndarray
    resting: bool  # stands on a surface (gets a contact shadow)
    prims: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class _Surface:
    x0: float
    x1: float
    y0: float
    y1: float
    z: float
    kinds: frozenset[str] | None = None  # None: any ordinary kind
    row: bool = False  # shelf: objects line up at the front edge (y0)
    hang: bool = False  # rail: z is the top of the object


@dataclass
class _Hand:
    side: str
    palm: np.ndarray
    segments: list[tuple[np.ndarray, np.ndarray]]  # wrist-elbow, elbow-shoulder


@dataclass
class _Scene:
    prims: list[_Prim] = field(default_factory=list)
    materials: list[_Mat] = field(default_factory=list)
    objects: list[_Object] = field(default_factory=list)
    surfaces: list[_Surface] = field(default_factory=list)
    hands: list[_Hand] = field(default_factory=list)
    rests: list[_Surface] = field(default_factory=list)  # where idle hands may rest
    eye: np.ndarray = field(default_factory=lambda: np.zeros(3))
    R: np.ndarray = field(default_factory=lambda: np.eye(3))  # camera to world (columns x, y, z)
    pitch: float = 0.0
    yaw: float = 0.0
    roll: float = 0.0
    seated: bool = False
    kind: str = "tactile"
    action: int = 0
    same_kind: int = 0
    light: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    arrays: _PrimArrays | None = None  # cache for the ray caster

    def material(self, mat: _Mat) -> int:
        self.materials.append(mat)
        return len(self.materials) - 1

    def add(self, shape: int, centre, size, mat: int, *, axes=None, obj: int = _BACKGROUND) -> int:
        self.prims.append(
            _Prim(
                shape=shape,
                centre=np.asarray(centre, dtype=np.float64),
                axes=np.eye(3) if axes is None else np.asarray(axes, dtype=np.float64),
                size=np.asarray(size, dtype=np.float64),
                material=mat,
                obj=obj,
            )
        )
        return len(self.prims) - 1

    def block(self, lo, hi, mat: int) -> int:
        """Add an axis-aligned background box from its corners."""
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        return self.add(_BOX, (lo + hi) / 2.0, (hi - lo) / 2.0, mat)

    def room(self, lo, hi, faces: list[_Mat]) -> None:
        """Add the room (seen from inside); faces: x-, x+, y-, y+, floor, ceiling."""
        first = len(self.materials)
        for mat in faces:
            self.material(mat)
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        self.add(_ROOM, (lo + hi) / 2.0, (hi - lo) / 2.0, first)


# ---------------------------------------------------------------------------
# Small helpers
# ---------------------------------------------------------------------------


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-12)


def _frame_from(u: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Axes (w, a, u) with u the main direction and a orthogonalised against it."""
    u = _unit(u)
    a = _unit(a - np.dot(a, u) * u)
    w = np.cross(a, u)
    return np.stack([w, a, u], axis=1)


def _jitter(rgb, rng: np.random.Generator, amount: float = 0.05) -> tuple[float, float, float]:
    out = np.clip(np.asarray(rgb, dtype=np.float64) * (1.0 + rng.uniform(-amount, amount, 3)), 0.0, 1.0)
    return (float(out[0]), float(out[1]), float(out[2]))


def _random_colour(rng: np.random.Generator, *, sat=(0.35, 0.85), val=(0.4, 0.9)) -> tuple[float, float, float]:
    r, g, b = colorsys.hsv_to_rgb(rng.uniform(0.0, 1.0), rng.uniform(*sat), rng.uniform(*val))
    return (r, g, b)


def _darker(rgb, f: float = 0.55) -> tuple[float, float, float]:
    return (rgb[0] * f, rgb[1] * f, rgb[2] * f)


def _point_box_distance(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    return float(np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0)))


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


# ---------------------------------------------------------------------------
# Object kinds
# ---------------------------------------------------------------------------

_DARK = (0.08, 0.08, 0.09)
_METAL = (0.62, 0.63, 0.65)
_WHITE = (0.93, 0.93, 0.91)


def _kind_mug(c, c2):
    body = _Mat(c, spec=0.15)
    return [
        _Part(_CYL, (0, 0, 0.05), (0.04, 0.04, 0.05), body),
        _Part(_BOX, (0.048, 0, 0.05), (0.012, 0.006, 0.028), body),
    ]


def _kind_cup(c, c2):
    return [
        _Part(_CYL, (0, 0, 0.045), (0.035, 0.035, 0.045), _Mat(c, c2, _LABEL, spec=0.1)),
        _Part(_CYL, (0, 0, 0.0915), (0.036, 0.036, 0.0015), _Mat(_WHITE)),
    ]


def _kind_glass(c, c2):
    tint = (0.55 + 0.35 * c[0], 0.6 + 0.35 * c[1], 0.65 + 0.3 * c[2])
    return [_Part(_CYL, (0, 0, 0.06), (0.03, 0.03, 0.06), _Mat(tint, spec=0.5))]


def _kind_bottle(c, c2):
    return [
        _Part(_CYL, (0, 0, 0.09), (0.034, 0.034, 0.09), _Mat(c, c2, _LABEL, spec=0.3)),
        _Part(_CYL, (0, 0, 0.21), (0.015, 0.015, 0.03), _Mat(c, spec=0.3)),
        _Part(_CYL, (0, 0, 0.245), (0.017, 0.017, 0.008), _Mat(c2)),
    ]


def _kind_can(c, c2):
    return [
        _Part(_CYL, (0, 0, 0.06), (0.033, 0.033, 0.06), _Mat(c, c2, _LABEL, spec=0.35)),
        _Part(_CYL, (0, 0, 0.1215), (0.03, 0.03, 0.0015), _Mat(_METAL, spec=0.4)),
    ]


def _kind_jar(c, c2):
    return [
        _Part(_CYL, (0, 0, 0.055), (0.043, 0.043, 0.055), _Mat(c, c2, _LABEL, spec=0.2)),
        _Part(_CYL, (0, 0, 0.118), (0.045, 0.045, 0.008), _Mat(c2, spec=0.3)),
    ]


def _kind_pot(c, c2):
    body = _Mat(c, spec=0.3)
    return [
        _Part(_CYL, (0, 0, 0.07), (0.105, 0.105, 0.07), body),
        _Part(_CYL, (0, 0, 0.144), (0.1, 0.1, 0.004), _Mat(_darker(c, 0.7), spec=0.3)),
        _Part(_BOX, (0.125, 0, 0.11), (0.022, 0.014, 0.008), _Mat(_DARK)),
        _Part(_BOX, (-0.125, 0, 0.11), (0.022, 0.014, 0.008), _Mat(_DARK)),
    ]


def _kind_pan(c, c2):
    return [
        _Part(_CYL, (0, 0, 0.022), (0.12, 0.12, 0.022), _Mat(_darker(c, 0.45), spec=0.2)),
        _Part(_CYL, (0, 0, 0.0445), (0.108, 0.108, 0.0005), _Mat((0.12, 0.12, 0.13))),
        _Part(_BOX, (0.2, 0, 0.035), (0.085, 0.013, 0.009), _Mat(_DARK)),
    ]


def _kind_plate(c, c2):
    return [
        _Part(_CYL, (0, 0, 0.009), (0.115, 0.115, 0.009), _Mat(c, spec=0.25)),
        _Part(_CYL, (0, 0, 0.0185), (0.075, 0.075, 0.0005), _Mat(tuple(0.5 + 0.5 * x for x in c), spec=0.1)),
    ]


def _kind_bowl(c, c2):
    return [_Part(_ELL, (0, 0, 0.04), (0.075, 0.075, 0.04), _Mat(c, spec=0.2))]


def _kind_fruit(c, c2):
    return [
        _Part(_ELL, (0, 0, 0.04), (0.04, 0.04, 0.038), _Mat(c, spec=0.3)),
        _Part(_CYL, (0, 0, 0.082), (0.003, 0.003, 0.008), _Mat((0.3, 0.2, 0.1))),
    ]


def _kind_cutting_board(c, c2):
    wood = (0.72 + 0.1 * c[0], 0.55 + 0.1 * c[1], 0.35 + 0.1 * c[2])
    return [_Part(_BOX, (0, 0, 0.011), (0.18, 0.12, 0.011), _Mat(wood, _darker(wood, 0.8), _WOOD, 60.0))]


def _kind_cereal(c, c2):
    return [_Part(_BOX, (0, 0, 0.14), (0.095, 0.033, 0.14), _Mat(c, c2, _LABEL))]


def _kind_carton(c, c2):
    return [
        _Part(_BOX, (0, 0, 0.1), (0.045, 0.045, 0.1), _Mat(c, c2, _LABEL)),
        _Part(_BOX, (0, 0, 0.21), (0.045, 0.01, 0.012), _Mat(c)),
    ]


def _kind_packet(c, c2):
    return [_Part(_BOX, (0, 0, 0.09), (0.07, 0.025, 0.09), _Mat(c, c2, _LABEL))]


def _kind_keyboard(c, c2):
    base = (0.15 + 0.7 * c[0] * 0.2, 0.15 + 0.7 * c[1] * 0.2, 0.15 + 0.7 * c[2] * 0.2)
    return [_Part(_BOX, (0, 0, 0.012), (0.215, 0.07, 0.012), _Mat(base, (0.04, 0.04, 0.04), _KEYS, 55.0))]


def _kind_mouse(c, c2):
    return [_Part(_ELL, (0, 0, 0.018), (0.032, 0.055, 0.02), _Mat(c, spec=0.3))]


def _kind_laptop(c, c2):
    shell = _Mat(c, spec=0.3)
    tilt = math.radians(15.0)
    ax = _rot_x(-tilt)
    hinge = np.array([0.0, 0.11, 0.02])
    centre = hinge + ax @ np.array([0.0, 0.0, 0.105])
    return [
        _Part(_BOX, (0, 0, 0.01), (0.16, 0.11, 0.01), _Mat(c, (0.05, 0.05, 0.05), _KEYS, 60.0, spec=0.2)),
        _Part(_BOX, tuple(centre), (0.16, 0.006, 0.105), _Mat((0.06, 0.06, 0.07), c2, _SCREEN, spec=0.2), ax),
        _Part(_BOX, tuple(centre + ax @ np.array([0.0, 0.007, 0.0])), (0.16, 0.001, 0.105), shell, ax),
    ]


def _kind_monitor(c, c2):
    dark = _Mat(_darker(c, 0.25), spec=0.2)
    return [
        _Part(_CYL, (0, 0, 0.008), (0.09, 0.09, 0.008), dark),
        _Part(_BOX, (0, 0.02, 0.13), (0.02, 0.012, 0.12), dark),
        _Part(_BOX, (0, 0, 0.33), (0.27, 0.015, 0.165), _Mat((0.05, 0.05, 0.06), c2, _SCREEN, spec=0.2)),
    ]


def _kind_paper(c, c2):
    sheet = (0.92 + 0.06 * c[0], 0.92 + 0.06 * c[1], 0.9 + 0.06 * c[2])
    return [_Part(_BOX, (0, 0, 0.0015), (0.105, 0.148, 0.0015), _Mat(sheet, _darker(c2, 0.7), _PAPER, 120.0))]


def _kind_notebook(c, c2):
    return [
        _Part(_BOX, (0, 0, 0.008), (0.1, 0.14, 0.008), _Mat(c, spec=0.1)),
        _Part(_BOX, (0.09, 0, 0.008), (0.012, 0.14, 0.0085), _Mat(_darker(c, 0.6))),
    ]


def _kind_book(c, c2):
    return [
        _Part(_BOX, (0, 0, 0.016), (0.085, 0.12, 0.016), _Mat(c, c2, _LABEL)),
        _Part(_BOX, (0.006, 0, 0.016), (0.082, 0.118, 0.0165), _Mat((0.9, 0.88, 0.8))),
    ]


def _kind_phone(c, c2):
    return [
        _Part(_BOX, (0, 0, 0.005), (0.037, 0.075, 0.005), _Mat(_darker(c, 0.35), spec=0.4)),
        _Part(_BOX, (0, 0, 0.0102), (0.033, 0.068, 0.0003), _Mat((0.04, 0.04, 0.05), c2, _SCREEN, spec=0.5)),
    ]


def _kind_remote(c, c2):
    return [
        _Part(_BOX, (0, 0, 0.011), (0.025, 0.09, 0.011), _Mat(_darker(c, 0.3), spec=0.2)),
        _Part(_BOX, (0, 0.05, 0.0225), (0.012, 0.012, 0.0015), _Mat(c2)),
    ]


def _kind_tv(c, c2):
    dark = _Mat((0.05, 0.05, 0.055), spec=0.3)
    return [
        _Part(_BOX, (0, 0, 0.012), (0.16, 0.09, 0.012), dark),
        _Part(_BOX, (0, 0.01, 0.06), (0.03, 0.02, 0.05), dark),
        _Part(_BOX, (0, 0, 0.37), (0.45, 0.025, 0.26), _Mat((0.04, 0.04, 0.05), c2, _SCREEN, spec=0.3)),
    ]


def _kind_lamp(c, c2):
    return [
        _Part(_CYL, (0, 0, 0.015), (0.07, 0.07, 0.015), _Mat(_darker(c, 0.5), spec=0.3)),
        _Part(_CYL, (0, 0, 0.2), (0.012, 0.012, 0.19), _Mat(_METAL, spec=0.4)),
        _Part(_CYL, (0, 0, 0.43), (0.12, 0.12, 0.09), _Mat((0.9 + 0.1 * c[0], 0.85 + 0.1 * c[1], 0.7 + 0.1 * c[2]))),
    ]


def _kind_suitcase(c, c2):
    return [
        _Part(_BOX, (0, 0, 0.3), (0.2, 0.12, 0.28), _Mat(c, _darker(c, 0.7), _LABEL, spec=0.2)),
        _Part(_BOX, (0, 0, 0.6), (0.06, 0.012, 0.02), _Mat(_DARK)),
    ]


def _kind_towel(c, c2):
    return [_Part(_BOX, (0, 0, 0.025), (0.17, 0.12, 0.025), _Mat(c, _darker(c, 0.85), _FABRIC, 90.0))]


def _kind_shirt(c, c2):
    return [
        _Part(_BOX, (0, 0, 0.02), (0.16, 0.2, 0.02), _Mat(c, _darker(c, 0.85), _FABRIC, 110.0)),
        _Part(_BOX, (0, -0.17, 0.041), (0.07, 0.025, 0.002), _Mat(_darker(c, 0.75))),
    ]


def _kind_shoe(c, c2):
    return [
        _Part(_ELL, (0, 0, 0.045), (0.045, 0.13, 0.045), _Mat(c, spec=0.3)),
        _Part(_BOX, (0, 0, 0.009), (0.047, 0.13, 0.009), _Mat(c2)),
    ]


def _kind_handbag(c, c2):
    body = _Mat(c, spec=0.25)
    strap = _Mat(_darker(c, 0.6))
    return [
        _Part(_BOX, (0, 0, 0.1), (0.14, 0.06, 0.1), body),
        _Part(_BOX, (0, 0, 0.235), (0.08, 0.008, 0.008), strap),
        _Part(_BOX, (0.075, 0, 0.215), (0.008, 0.008, 0.02), strap),
        _Part(_BOX, (-0.075, 0, 0.215), (0.008, 0.008, 0.02), strap),
    ]


def _kind_hat(c, c2):
    return [
        _Part(_ELL, (0, 0, 0.01), (0.09, 0.1, 0.08), _Mat(c, _darker(c, 0.8), _FABRIC, 120.0)),
        _Part(_CYL, (0, 0, 0.006), (0.15, 0.15, 0.005), _Mat(_darker(c, 0.8))),
        _Part(_CYL, (0, 0, 0.025), (0.092, 0.092, 0.012), _Mat(c2)),
    ]


def _kind_shoebox(c, c2):
    return [
        _Part(_BOX, (0, 0, 0.06), (0.17, 0.1, 0.06), _Mat(c)),
        _Part(_BOX, (0, 0, 0.124), (0.175, 0.105, 0.006), _Mat(c2)),
    ]


def _kind_sponge(c, c2):
    return [
        _Part(_BOX, (0, 0, 0.014), (0.048, 0.032, 0.014), _Mat((0.95, 0.8, 0.25))),
        _Part(_BOX, (0, 0, 0.032), (0.048, 0.032, 0.004), _Mat(_darker(c, 0.8))),
    ]


def _kind_soap(c, c2):
    return [
        _Part(_CYL, (0, 0, 0.08), (0.032, 0.032, 0.08), _Mat(c, spec=0.4)),
        _Part(_CYL, (0, 0, 0.18), (0.009, 0.009, 0.02), _Mat(_WHITE)),
        _Part(_BOX, (0, -0.02, 0.195), (0.006, 0.025, 0.006), _Mat(_WHITE)),
    ]


def _kind_garment(c, c2):
    # Hangs from a rail: the origin is at the top (the hook).
    return [
        _Part(_BOX, (0, 0, -0.36), (0.22, 0.015, 0.33), _Mat(c, _darker(c, 0.85), _FABRIC, 100.0)),
        _Part(_BOX, (0, 0, -0.03), (0.17, 0.006, 0.006), _Mat((0.35, 0.25, 0.15))),
    ]


@dataclass(frozen=True)
class _Kind:
    build: Callable[[tuple, tuple], list[_Part]]
    palette: tuple[tuple[float, float, float], ...] = ()  # typical colours (used half the time)
    flat: bool = False  # a hand rests on top instead of grasping the side
    two_hands: bool = False  # often handled with both hands
    tilt: float = 0.25  # max tilt (rad) when held
    facing: bool = False  # faces the wearer (small yaw only)
    holdable: bool = True


_KINDS: dict[str, _Kind] = {
    "mug": _Kind(_kind_mug, (_WHITE, (0.2, 0.3, 0.6), (0.7, 0.2, 0.2))),
    "cup": _Kind(_kind_cup, (_WHITE, (0.9, 0.85, 0.7))),
    "glass": _Kind(_kind_glass),
    "bottle": _Kind(_kind_bottle, ((0.2, 0.5, 0.25), (0.5, 0.3, 0.15), (0.3, 0.5, 0.75))),
    "can": _Kind(_kind_can),
    "jar": _Kind(_kind_jar),
    "pot": _Kind(_kind_pot, (_METAL, (0.55, 0.15, 0.12), (0.2, 0.2, 0.22)), two_hands=True, tilt=0.1),
    "pan": _Kind(_kind_pan, (_DARK, (0.3, 0.3, 0.32)), tilt=0.15),
    "plate": _Kind(_kind_plate, (_WHITE, (0.9, 0.88, 0.8), (0.35, 0.5, 0.75)), flat=True, tilt=0.8),
    "bowl": _Kind(_kind_bowl, (_WHITE, (0.8, 0.6, 0.4)), tilt=0.3),
    "fruit": _Kind(_kind_fruit, ((0.75, 0.1, 0.1), (0.95, 0.55, 0.1), (0.5, 0.75, 0.2), (0.95, 0.85, 0.2))),
    "cutting board": _Kind(_kind_cutting_board, flat=True, two_hands=True, tilt=0.3),
    "cereal box": _Kind(_kind_cereal, facing=True),
    "carton": _Kind(_kind_carton, facing=True),
    "packet": _Kind(_kind_packet, facing=True),
    "keyboard": _Kind(_kind_keyboard, flat=True, two_hands=True, facing=True, tilt=0.0),
    "mouse": _Kind(_kind_mouse, (_DARK, (0.8, 0.8, 0.8)), flat=True, facing=True, tilt=0.0),
    "laptop": _Kind(
        _kind_laptop, ((0.7, 0.7, 0.72), (0.15, 0.15, 0.17)), flat=True, two_hands=True, facing=True, tilt=0.0
    ),
    "monitor": _Kind(_kind_monitor, (_DARK,), facing=True, holdable=False),
    "paper": _Kind(_kind_paper, flat=True, tilt=0.4),
    "notebook": _Kind(_kind_notebook, flat=True, tilt=0.4),
    "book": _Kind(_kind_book, flat=True, tilt=0.4),
    "phone": _Kind(_kind_phone, flat=True, tilt=0.5),
    "remote": _Kind(_kind_remote, flat=True, tilt=0.4),
    "tv": _Kind(_kind_tv, (_DARK,), facing=True, holdable=False),
    "lamp": _Kind(_kind_lamp, holdable=False),
    "suitcase": _Kind(_kind_suitcase, facing=True, holdable=False),
    "towel": _Kind(_kind_towel, (_WHITE,), flat=True, tilt=0.3),
    "shirt": _Kind(_kind_shirt, flat=True, tilt=0.3),
    "shoe": _Kind(_kind_shoe, tilt=0.3),
    "handbag": _Kind(_kind_handbag, facing=True, tilt=0.2),
    "hat": _Kind(_kind_hat, tilt=0.3),
    "shoebox": _Kind(_kind_shoebox, ((0.85, 0.8, 0.7), (0.9, 0.5, 0.2)), two_hands=True, facing=True, tilt=0.2),
    "sponge": _Kind(_kind_sponge, ((0.2, 0.6, 0.25),), tilt=0.3),
    "soap": _Kind(_kind_soap),
    "garment": _Kind(_kind_garment, facing=True, holdable=False),
}

_SPECIAL_KINDS = frozenset({"tv", "monitor", "lamp", "garment", "suitcase"})


def _object_colours(kind: str, rng: np.random.Generator) -> tuple[tuple, tuple]:
    spec = _KINDS[kind]
    if spec.palette and rng.random() < 0.5:
        c = _jitter(spec.palette[int(rng.integers(len(spec.palette)))], rng, 0.06)
    else:
        c = _random_colour(rng)
    return c, _random_colour(rng, sat=(0.2, 0.9), val=(0.3, 0.95))


@dataclass
class _Candidate:
    name: str
    colour: tuple
    colour2: tuple
    parts: list[_Part]
    rot: np.ndarray
    pos: np.ndarray  # world position of the object's origin
    lo: np.ndarray
    hi: np.ndarray
    resting: bool = True

    @property
    def centre(self) -> np.ndarray:
        return (self.lo + self.hi) / 2.0


_BOX_SIGNS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=np.float64)


def _corners(parts: list[_Part]) -> np.ndarray:
    """(8 * len(parts), 3) corners of the parts' boxes in the object's frame."""
    out = []
    for part in parts:
        axes = np.eye(3) if part.axes is None else part.axes
        out.append(np.asarray(part.centre) + (_BOX_SIGNS * np.asarray(part.size)) @ axes.T)
    return np.concatenate(out)


def _make_candidate(name, colour, colour2, parts, rot, pos, resting=True, corners=None) -> _Candidate:
    corners = (_corners(parts) if corners is None else corners) @ rot.T + pos
    return _Candidate(name, colour, colour2, parts, rot, pos, corners.min(0), corners.max(0), resting)


def _local_extent(corners: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = corners @ rot.T
    return c.min(0), c.max(0)


def _commit(scene: _Scene, cand: _Candidate) -> int:
    oid = len(scene.objects)
    obj = _Object(cand.name, cand.colour, cand.centre, cand.lo, cand.hi, cand.resting)
    for part in cand.parts:
        axes = np.eye(3) if part.axes is None else part.axes
        mat = scene.material(part.mat)
        obj.prims.append(
            scene.add(
                part.shape, cand.pos + cand.rot @ np.asarray(part.centre), part.size, mat, axes=cand.rot @ axes, obj=oid
            )
        )
    scene.objects.append(obj)
    return oid


def _sample_on(
    surfaces: list[_Surface],
    name: str,
    colour: tuple,
    colour2: tuple,
    rng: np.random.Generator,
    accept: Callable[[_Candidate], bool],
    *,
    tries: int = 30,
) -> _Candidate | None:
    """Sample a pose for an object on one of the surfaces that allow its kind."""
    spec = _KINDS[name]
    allowed = [
        s
        for s in surfaces
        if (name in s.kinds if s.kinds is not None else name not in _SPECIAL_KINDS)
    ]
    if not allowed:
        return None
    areas = np.array([max(s.x1 - s.x0, 0.01) * max(s.y1 - s.y0, 0.05) for s in allowed])
    parts = _KINDS[name].build(colour, colour2)
    corners = _corners(parts)
    for _ in range(tries):
        surf = allowed[int(rng.choice(len(allowed), p=areas / areas.sum()))]
        if spec.facing or surf.row:
            yaw = rng.normal(0.0, 0.12)
        else:
            yaw = rng.uniform(-math.pi, math.pi)
        rot = _rot_z(yaw)
        lo, hi = _local_extent(corners, rot)
        x_lo, x_hi = surf.x0 - lo[0], surf.x1 - hi[0]
        if x_lo > x_hi:
            continue
        x = rng.uniform(x_lo, x_hi)
        if surf.row:
            y = surf.y0 - lo[1] + rng.uniform(0.005, 0.02)
        else:
            y_lo, y_hi = surf.y0 - lo[1], surf.y1 - hi[1]
            if y_lo > y_hi:
                y = (surf.y0 + surf.y1) / 2.0
            else:
                y = rng.uniform(y_lo, y_hi)
        z = surf.z - hi[2] if surf.hang else surf.z
        cand = _make_candidate(name, colour, colour2, parts, rot, np.array([x, y, z]), corners=corners)
        if accept(cand):
            return cand
    return None


# ---------------------------------------------------------------------------
# Materials for rooms and furniture
# ---------------------------------------------------------------------------


def _wall(rng, base=(0.85, 0.82, 0.75)) -> _Mat:
    return _Mat(_jitter(base, rng, 0.08))


def _floor(rng, kind: str) -> _Mat:
    if kind == "tiles":
        c = _jitter((0.78, 0.76, 0.72), rng, 0.1)
        return _Mat(c, _darker(c, 0.7), _TILES, float(rng.uniform(0.3, 0.6)))
    if kind == "wood":
        c = _jitter((0.6, 0.42, 0.26), rng, 0.12)
        return _Mat(c, _darker(c, 0.75), _TILES, float(rng.uniform(0.15, 0.25)))
    c = _jitter((0.45, 0.4, 0.38), rng, 0.2)
    return _Mat(c, _darker(c, 0.85), _FABRIC, 60.0)


def _wood(rng, base=(0.62, 0.44, 0.28)) -> _Mat:
    c = _jitter(base, rng, 0.12)
    return _Mat(c, _darker(c, 0.78), _WOOD, float(rng.uniform(25.0, 45.0)))


def _ceiling() -> _Mat:
    return _Mat((0.93, 0.93, 0.92))


# ---------------------------------------------------------------------------
# Activity layouts: furniture and the surfaces objects stand on
# ---------------------------------------------------------------------------


def _counter_with_cabinets(scene: _Scene, rng, x0, x1, y0, y1, top_z, top_mat: int, door_mat: int) -> None:
    scene.block((x0, y0 + 0.04, 0.0), (x1, y1, top_z - 0.04), door_mat)
    scene.block((x0, y0 + 0.02, 0.0), (x1, y0 + 0.05, 0.1), scene.material(_Mat((0.15, 0.15, 0.15))))
    scene.block((x0, y0, top_z - 0.04), (x1, y1, top_z), top_mat)


def _layout_cooking(scene: _Scene, rng: np.random.Generator, seated: bool) -> None:
    top = rng.uniform(0.88, 0.94)
    front = rng.uniform(0.22, 0.3)
    back = front + rng.uniform(0.58, 0.66)
    xl, xr = -rng.uniform(1.6, 2.4), rng.uniform(1.6, 2.4)
    tile = _jitter((0.85, 0.85, 0.82), rng, 0.1)
    scene.room(
        (xl, -rng.uniform(1.5, 2.5), 0.0),
        (xr, back, rng.uniform(2.4, 2.7)),
        [
            _wall(rng),
            _wall(rng),
            _wall(rng),
            _Mat(tile,
            _darker(tile, 0.8),
            _TILES, 0.15),
            _floor(rng, "tiles"),
            _ceiling(),
        ],
    )
    stone = _jitter(rng.choice([(0.85, 0.84, 0.8), (0.3, 0.3, 0.32), (0.6, 0.55, 0.5)]), rng, 0.08)
    top_mat = scene.material(_Mat(stone, _darker(stone, 0.9), _FABRIC, 200.0, spec=0.2))
    door_rgb = rng.choice([(0.9, 0.9, 0.88), (0.35, 0.45, 0.55), (0.55, 0.4, 0.28)])
    door = scene.material(_Mat(_jitter(door_rgb, rng, 0.08)))
    _counter_with_cabinets(scene, rng, xl, xr, front, back, top, top_mat, door)
    surfaces = [_Surface(xl + 0.05, xr - 0.05, front + 0.02, back - 0.04, top)]
    if rng.random() < 0.6:  # L-shaped kitchen: a counter along the left wall
        side_x = xl + rng.uniform(0.58, 0.65)
        y_start = -rng.uniform(0.6, 1.2)
        _counter_with_cabinets(scene, rng, xl, side_x, y_start, front, top, top_mat, door)
        surfaces.append(_Surface(xl + 0.04, side_x - 0.04, y_start + 0.04, front - 0.02, top))
    # Upper cabinets.
    upper_z = rng.uniform(1.42, 1.55)
    scene.block((xl, back - 0.34, upper_z), (xr, back, upper_z + 0.7), door)
    # Stove with burners.
    sx = rng.uniform(-0.6, 0.5)
    hob = scene.material(_Mat((0.08, 0.08, 0.09), spec=0.5))
    scene.block((sx - 0.3, front + 0.03, top), (sx + 0.3, front + 0.55, top + 0.01), hob)
    ring = scene.material(_Mat((0.22, 0.22, 0.24)))
    for bx in (-0.15, 0.15):
        for by in (0.16, 0.4):
            scene.add(_CYL, (sx + bx, front + by, top + 0.012), (0.07, 0.07, 0.002), ring)
    scene.surfaces.extend(surfaces)
    scene.rests.append(_Surface(-0.35, 0.35, front, front + 0.2, top))


def _layout_dining(scene: _Scene, rng: np.random.Generator, seated: bool) -> None:
    top = rng.uniform(0.72, 0.77)
    near = rng.uniform(0.15, 0.26)
    far = near + rng.uniform(0.8, 1.0)
    half_w = rng.uniform(0.55, 0.8)
    cx = rng.uniform(-0.1, 0.1)
    back = far + rng.uniform(0.9, 1.6)
    scene.room(
        (-rng.uniform(1.8, 2.8), -rng.uniform(1.2, 2.0), 0.0),
        (rng.uniform(1.8, 2.8), back, rng.uniform(2.5, 2.8)),
        [_wall(rng), _wall(rng), _wall(rng), _wall(rng, (0.75, 0.8, 0.85)), _floor(rng, "wood"), _ceiling()],
    )
    if rng.random() < 0.5:
        c = _random_colour(rng, sat=(0.1, 0.5), val=(0.7, 0.95))
        top_mat = scene.material(_Mat(c, _darker(c, 0.85), _FABRIC, 80.0))
    else:
        top_mat = scene.material(_wood(rng))
    scene.block((cx - half_w, near, top - 0.04), (cx + half_w, far, top), top_mat)
    leg = scene.material(_wood(rng, (0.4, 0.28, 0.18)))
    for lx in (cx - half_w + 0.04, cx + half_w - 0.08):
        for ly in (near + 0.04, far - 0.08):
            scene.block((lx, ly, 0.0), (lx + 0.04, ly + 0.04, top - 0.04), leg)
    # Chairs across the table.
    chair = scene.material(_wood(rng, (0.45, 0.3, 0.2)))
    for chx in rng.uniform(-half_w + 0.25, half_w - 0.25, size=int(rng.integers(1, 3))):
        x = cx + chx
        scene.block((x - 0.22, far + 0.1, 0.42), (x + 0.22, far + 0.52, 0.46), chair)
        scene.block((x - 0.22, far + 0.48, 0.46), (x + 0.22, far + 0.52, 0.95), chair)
        scene.block((x - 0.22, far + 0.1, 0.0), (x - 0.18, far + 0.14, 0.42), chair)
        scene.block((x + 0.18, far + 0.1, 0.0), (x + 0.22, far + 0.14, 0.42), chair)
    surfaces = [_Surface(cx - half_w + 0.03, cx + half_w - 0.03, near + 0.03, far - 0.03, top)]
    if rng.random() < 0.6:  # sideboard against the far wall
        sb_z = rng.uniform(0.8, 0.9)
        sx = rng.uniform(-0.8, 0.4)
        scene.block((sx, back - 0.45, 0.0), (sx + 1.2, back, sb_z), scene.material(_wood(rng)))
        surfaces.append(_Surface(sx + 0.03, sx + 1.17, back - 0.42, back - 0.03, sb_z))
    scene.surfaces.extend(surfaces)
    scene.rests.append(_Surface(-0.4, 0.4, near, near + 0.18, top))


_SHELF_PRODUCTS = ("cereal box", "can", "bottle", "jar", "carton", "packet")


def _layout_grocery(scene: _Scene, rng: np.random.Generator, seated: bool) -> None:
    front = rng.uniform(0.45, 0.6)
    depth = 0.42
    back = front + depth
    scene.room(
        (-rng.uniform(2.5, 3.5), -rng.uniform(1.6, 2.2), 0.0),
        (rng.uniform(2.5, 3.5), back + 0.01, rng.uniform(2.8, 3.4)),
        [_wall(rng), _wall(rng), _wall(rng), _wall(rng, (0.9, 0.9, 0.9)), _floor(rng, "tiles"), _ceiling()],
    )
    unit = _jitter(rng.choice([(0.85, 0.85, 0.85), (0.3, 0.32, 0.35), (0.8, 0.75, 0.6)]), rng, 0.05)
    unit_mat = scene.material(_Mat(unit, spec=0.2))
    board_mat = scene.material(_Mat(_darker(unit, 0.9), spec=0.3))
    x0, x1 = -2.4, 2.4
    scene.block((x0, back - 0.02, 0.0), (x1, back, 2.0), unit_mat)
    scene.block((x0, front, 0.0), (x1, back, 0.1), board_mat)
    boards = [0.1 + 0.38 * k + rng.uniform(-0.02, 0.02) for k in range(1, 5)]
    for z in boards:
        scene.block((x0, front, z - 0.025), (x1, back, z), board_mat)
        # Price rail on the shelf edge.
        rail = scene.material(_Mat(_jitter((0.9, 0.9, 0.85), rng, 0.05)))
        scene.block((x0, front - 0.01, z - 0.045), (x1, front, z), rail)
    scene.block((x0, front, 1.98), (x1, back, 2.0), board_mat)
    offset = rng.uniform(-0.5, 0.5)
    for k in range(-3, 4):
        ux = offset + 0.95 * k
        scene.block((ux - 0.015, front, 0.0), (ux + 0.015, back, 2.0), unit_mat)
    scene.surfaces.extend(_Surface(-1.2, 1.2, front + 0.01, back - 0.03, z, row=True) for z in [0.1, *boards])


def _layout_shopping(scene: _Scene, rng: np.random.Generator, seated: bool) -> None:
    top = rng.uniform(0.75, 0.88)
    near = rng.uniform(0.25, 0.38)
    far = near + rng.uniform(0.7, 0.9)
    half_w = rng.uniform(0.5, 0.7)
    cx = rng.uniform(-0.15, 0.15)
    wall_y = far + rng.uniform(0.8, 1.4)
    scene.room(
        (-rng.uniform(2.2, 3.0), -rng.uniform(1.5, 2.5), 0.0),
        (rng.uniform(2.2, 3.0), wall_y, rng.uniform(2.8, 3.2)),
        [
            _wall(rng),
            _wall(rng),
            _wall(rng),
            _wall(rng, (0.95, 0.93, 0.9)),
            _floor(rng, "wood" if rng.random() < 0.5 else "tiles"),
            _ceiling(),
        ],
    )
    table = scene.material(_Mat(_jitter(rng.choice([(0.95, 0.95, 0.95), (0.2, 0.2, 0.22)]), rng, 0.04), spec=0.2))
    scene.block((cx - half_w, near, top - 0.05), (cx + half_w, far, top), table)
    scene.block((cx - half_w + 0.05, near + 0.05, 0.0), (cx + half_w - 0.05, far - 0.05, top - 0.05), table)
    surfaces = [_Surface(cx - half_w + 0.03, cx + half_w - 0.03, near + 0.03, far - 0.03, top)]
    # Wall shelving behind the table.
    shelf_mat = scene.material(_wood(rng, (0.8, 0.7, 0.55)))
    for z in (0.4, 0.9, 1.4, 1.9):
        scene.block((-1.6, wall_y - 0.4, z - 0.03), (1.6, wall_y, z), shelf_mat)
        surfaces.append(_Surface(-1.55, 1.55, wall_y - 0.38, wall_y - 0.02, z, row=True))
    # A clothes rack to one side, rail running forward.
    side = 1.0 if rng.random() < 0.5 else -1.0
    rx = side * rng.uniform(0.75, 1.0)
    rail_z = rng.uniform(1.35, 1.5)
    metal = scene.material(_Mat(_METAL, spec=0.5))
    r0, r1 = rng.uniform(0.0, 0.3), rng.uniform(1.2, 1.6)
    scene.add(_CYL, (rx, (r0 + r1) / 2, rail_z), (0.012, 0.012, (r1 - r0) / 2), metal, axes=_rot_x(math.pi / 2))
    for ry in (r0, r1):
        scene.add(_CYL, (rx, ry, rail_z / 2), (0.015, 0.015, rail_z / 2), metal)
    surfaces.append(
        _Surface(rx - 0.001, rx + 0.001, r0 + 0.05, r1 - 0.05, rail_z, kinds=frozenset({"garment"}), hang=True)
    )
    scene.surfaces.extend(surfaces)


def _layout_hotel(scene: _Scene, rng: np.random.Generator, seated: bool) -> None:
    wall_y = rng.uniform(1.0, 1.45)
    xl, xr = -rng.uniform(1.4, 1.9), rng.uniform(2.0, 2.4)
    scene.room(
        (xl, -rng.uniform(1.5, 2.5), 0.0),
        (xr, wall_y, rng.uniform(2.4, 2.6)),
        [
            _wall(rng, (0.8, 0.75, 0.65)),
            _wall(rng, (0.8, 0.75, 0.65)),
            _wall(rng),
            _wall(rng, (0.75, 0.7, 0.6)),
            _floor(rng, "carpet"),
            _ceiling(),
        ],
    )
    # Dresser / desk along the front wall.
    dz = rng.uniform(0.74, 0.8)
    d0 = rng.uniform(-1.2, -0.8)
    d1 = rng.uniform(0.4, 0.7)
    dresser = scene.material(_wood(rng, (0.45, 0.3, 0.2)))
    scene.block((d0, wall_y - 0.5, 0.0), (d1, wall_y, dz), dresser)
    surfaces = [
        _Surface(d0 + 0.03, d1 - 0.03, wall_y - 0.47, wall_y - 0.05, dz),
        _Surface(max(d0, -0.9), min(d1, 0.7), wall_y - 0.3, wall_y - 0.08, dz, kinds=frozenset({"tv"})),
        _Surface(d0 + 0.05, d1 - 0.05, wall_y - 0.3, wall_y - 0.08, dz, kinds=frozenset({"lamp"})),
    ]
    # A picture above the dresser.
    px = rng.uniform(-0.6, 0.2)
    picture = scene.material(_Mat(_random_colour(rng), _random_colour(rng), _WOOD, 8.0))
    scene.block((px - 0.3, wall_y - 0.02, 1.45), (px + 0.3, wall_y, 1.85), picture)
    # Bed on the right.
    bx0 = rng.uniform(0.5, 0.75)
    by0, by1 = rng.uniform(-1.4, -1.0), wall_y - 0.6
    scene.block((bx0, by0, 0.0), (xr, by1, 0.3), scene.material(_wood(rng, (0.35, 0.25, 0.18))))
    sheet = _jitter(rng.choice([(0.95, 0.95, 0.93), (0.85, 0.8, 0.7), (0.5, 0.55, 0.65)]), rng, 0.04)
    mattress = scene.material(_Mat(sheet, _darker(sheet, 0.9), _FABRIC, 70.0))
    scene.block((bx0 + 0.02, by0 + 0.02, 0.3), (xr, by1 - 0.02, 0.55), mattress)
    pillow = scene.material(_Mat(_jitter((0.96, 0.96, 0.95), rng, 0.03)))
    for k in range(2):
        scene.add(_ELL, (bx0 + 0.35 + 0.6 * k, by1 - 0.25, 0.6), (0.27, 0.16, 0.07), pillow)
    surfaces.append(_Surface(bx0 + 0.1, min(xr - 0.1, bx0 + 1.3), by0 + 0.3, by1 - 0.5, 0.55))
    # Luggage space on the floor to the left.
    surfaces.append(_Surface(xl + 0.1, -0.5, 0.3, wall_y - 0.6, 0.0, kinds=frozenset({"suitcase"})))
    scene.surfaces.extend(surfaces)
    scene.rests.append(_Surface(bx0 + 0.05, bx0 + 0.5, -0.2, 0.4, 0.55))


def _layout_desk(scene: _Scene, rng: np.random.Generator, seated: bool) -> None:
    top = rng.uniform(0.71, 0.76)
    near = rng.uniform(0.16, 0.26)
    far = near + rng.uniform(0.6, 0.75)
    x0, x1 = -rng.uniform(0.6, 0.9), rng.uniform(0.6, 0.9)
    scene.room(
        (-rng.uniform(1.5, 2.5), -rng.uniform(1.5, 2.5), 0.0),
        (rng.uniform(1.5, 2.5), far + 0.01, rng.uniform(2.4, 2.7)),
        [
            _wall(rng),
            _wall(rng),
            _wall(rng),
            _wall(rng, (0.9, 0.9, 0.88)),
            _floor(rng, "wood" if rng.random() < 0.6 else "carpet"),
            _ceiling(),
        ],
    )
    if rng.random() < 0.5:
        desk = scene.material(_wood(rng))
    else:
        desk_rgb = rng.choice([(0.95, 0.95, 0.94), (0.25, 0.25, 0.27)])
        desk = scene.material(_Mat(_jitter(desk_rgb, rng, 0.04), spec=0.2))
    scene.block((x0, near, top - 0.03), (x1, far, top), desk)
    scene.block((x0, near + 0.02, 0.0), (x0 + 0.03, far, top - 0.03), desk)
    scene.block((x1 - 0.03, near + 0.02, 0.0), (x1, far, top - 0.03), desk)
    surfaces = [
        _Surface(x0 + 0.03, x1 - 0.03, near + 0.03, far - 0.03, top),
        _Surface(-0.5, 0.5, far - 0.3, far - 0.1, top, kinds=frozenset({"monitor", "laptop"})),
        _Surface(x0 + 0.05, x1 - 0.05, far - 0.25, far - 0.06, top, kinds=frozenset({"lamp"})),
    ]
    if rng.random() < 0.6:  # wall shelf with books
        sz = rng.uniform(1.35, 1.5)
        scene.block((x0, far - 0.25, sz - 0.025), (x1, far, sz), scene.material(_wood(rng)))
        shelf_kinds = frozenset({"book", "mug", "bottle"})
        surfaces.append(_Surface(x0 + 0.02, x1 - 0.02, far - 0.23, far - 0.02, sz, kinds=shelf_kinds))
    scene.surfaces.extend(surfaces)
    scene.rests.append(_Surface(-0.4, 0.4, near, near + 0.15, top))


def _layout_dishwashing(scene: _Scene, rng: np.random.Generator, seated: bool) -> None:
    top = rng.uniform(0.88, 0.94)
    front = rng.uniform(0.2, 0.28)
    back = front + rng.uniform(0.58, 0.65)
    xl, xr = -rng.uniform(1.5, 2.2), rng.uniform(1.5, 2.2)
    tile = _jitter((0.8, 0.85, 0.88), rng, 0.08)
    scene.room(
        (xl, -rng.uniform(1.5, 2.5), 0.0),
        (xr, back, rng.uniform(2.4, 2.7)),
        [
            _wall(rng),
            _wall(rng),
            _wall(rng),
            _Mat(tile,
            _darker(tile, 0.8),
            _TILES, 0.12),
            _floor(rng, "tiles"),
            _ceiling(),
        ],
    )
    stone = _jitter(rng.choice([(0.85, 0.84, 0.8), (0.3, 0.3, 0.32), (0.55, 0.5, 0.45)]), rng, 0.08)
    top_mat = scene.material(_Mat(stone, _darker(stone, 0.9), _FABRIC, 200.0, spec=0.2))
    door = scene.material(_Mat(_jitter(rng.choice([(0.9, 0.9, 0.88), (0.4, 0.5, 0.45)]), rng, 0.08)))
    steel = scene.material(_Mat((0.6, 0.62, 0.64), spec=0.6))
    # Sink opening (sx0..sx1, sy0..sy1), basin floor at `bottom`.
    sxc = rng.uniform(-0.2, 0.2)
    sx0, sx1 = sxc - rng.uniform(0.25, 0.32), sxc + rng.uniform(0.25, 0.32)
    sy0, sy1 = front + 0.08, front + rng.uniform(0.44, 0.5)
    bottom = top - rng.uniform(0.18, 0.22)
    scene.block((xl, front + 0.02, 0.0), (xr, back, bottom), door)  # cabinets below
    for lo, hi in (
        ((xl, front, bottom), (sx0, back, top)),
        ((sx1, front, bottom), (xr, back, top)),
        ((sx0, front, bottom), (sx1, sy0, top)),
        ((sx0, sy1, bottom), (sx1, back, top)),
    ):
        scene.block(lo, hi, top_mat)
    # Steel liners make the basin walls and floor.
    scene.block((sx0, sy0, bottom), (sx1, sy1, bottom + 0.005), steel)
    scene.block((sx0, sy0, bottom), (sx0 + 0.006, sy1, top - 0.002), steel)
    scene.block((sx1 - 0.006, sy0, bottom), (sx1, sy1, top - 0.002), steel)
    scene.block((sx0, sy0, bottom), (sx1, sy0 + 0.006, top - 0.002), steel)
    scene.block((sx0, sy1 - 0.006, bottom), (sx1, sy1, top - 0.002), steel)
    # Tap.
    tx = sxc + rng.uniform(-0.05, 0.05)
    scene.add(_CYL, (tx, sy1 + 0.06, top + 0.13), (0.018, 0.018, 0.13), steel)
    scene.add(_BOX, (tx, sy1 - 0.04, top + 0.25), (0.014, 0.1, 0.012), steel)
    # Window above the sink.
    scene.block((sxc - 0.5, back - 0.01, 1.2), (sxc + 0.5, back, 2.0), scene.material(_Mat((0.85, 0.9, 0.97))))
    upper_z = rng.uniform(1.45, 1.55)
    scene.block((xl, back - 0.33, upper_z), (sxc - 0.6, back, upper_z + 0.7), door)
    scene.block((sxc + 0.6, back - 0.33, upper_z), (xr, back, upper_z + 0.7), door)
    dish_kinds = frozenset({"plate", "bowl", "cup", "mug", "pan", "glass", "pot", "sponge"})
    scene.surfaces.extend(
        [
            _Surface(sx0 + 0.01, sx1 - 0.01, sy0 + 0.01, sy1 - 0.01, bottom + 0.005, kinds=dish_kinds),
            _Surface(xl + 0.05, sx0 - 0.03, front + 0.03, back - 0.05, top),
            _Surface(sx1 + 0.03, xr - 0.05, front + 0.03, back - 0.05, top),
        ]
    )
    scene.rests.append(_Surface(-0.35, 0.35, front, front + 0.07, top))


@dataclass(frozen=True)
class _Activity:
    layout: Callable[[_Scene, np.random.Generator, bool], None]
    seated_prob: float
    tactile_prob: float
    tactile_kinds: tuple[str, ...]
    visual_kinds: tuple[str, ...]
    distractor_kinds: tuple[str, ...]
    n_distractors: tuple[int, int]
    shelf_fill: bool = False
    garments: bool = False


_STANDING_EYE = (1.52, 1.72)
_SKIN_TONES = ((0.87, 0.68, 0.55), (0.75, 0.55, 0.42), (0.55, 0.38, 0.27), (0.36, 0.24, 0.17), (0.93, 0.76, 0.64))
_SEATED_EYE = (1.12, 1.28)

_ACTIVITY_SPECS: dict[str, _Activity] = {
    "cooking": _Activity(
        _layout_cooking, 0.0, 0.72,
        ("pot", "pan", "cutting board", "mug", "bottle", "jar", "bowl", "fruit", "plate"),
        ("pot", "pan", "cutting board", "bowl", "jar", "bottle", "fruit", "plate"),
        ("pot", "pan", "cutting board", "mug", "bottle", "jar", "bowl", "fruit", "plate", "can", "cup", "soap"),
        (5, 9),
    ),
    "dining": _Activity(
        _layout_dining, 0.9, 0.7,
        ("cup", "glass", "mug", "bowl", "plate", "bottle", "fruit"),
        ("plate", "bowl", "bottle", "glass", "cup", "fruit"),
        ("cup", "glass", "mug", "bowl", "plate", "bottle", "fruit", "jar"),
        (5, 10),
    ),
    "grocery": _Activity(
        _layout_grocery, 0.0, 0.65,
        _SHELF_PRODUCTS, _SHELF_PRODUCTS, _SHELF_PRODUCTS, (0, 0), shelf_fill=True,
    ),
    "hotel": _Activity(
        _layout_hotel, 0.4, 0.45,
        ("remote", "phone", "bottle", "book", "cup", "towel"),
        ("tv", "tv", "lamp", "suitcase", "book", "towel", "bottle"),
        ("remote", "phone", "bottle", "book", "cup", "towel", "lamp", "suitcase", "tv"),
        (4, 7),
    ),
    "desk work": _Activity(
        _layout_desk, 0.9, 0.7,
        ("keyboard", "mouse", "paper", "notebook", "mug", "phone", "laptop"),
        ("monitor", "laptop", "paper", "notebook", "book", "mug"),
        ("keyboard", "mouse", "paper", "notebook", "mug", "phone", "laptop", "monitor", "book", "cup", "lamp"),
        (5, 9),
    ),
    "shopping": _Activity(
        _layout_shopping, 0.0, 0.6,
        ("shirt", "shoe", "handbag", "hat", "shoebox"),
        ("shirt", "shoe", "handbag", "hat", "shoebox", "garment"),
        ("shirt", "shoe", "handbag", "hat", "shoebox"),
        (6, 11), garments=True,
    ),
    "dishwashing": _Activity(
        _layout_dishwashing, 0.0, 0.8,
        ("plate", "bowl", "cup", "mug", "pan", "sponge", "glass"),
        ("plate", "bowl", "cup", "mug", "pan", "glass", "pot"),
        ("plate", "bowl", "cup", "mug", "pan", "glass", "pot", "sponge", "soap"),
        (5, 9),
    ),
}


# ---------------------------------------------------------------------------
# Scene sampling
# ---------------------------------------------------------------------------


def _camera_rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Camera-to-world rotation; columns are the camera x (right), y (down), z (forward)."""
    f = np.array([math.sin(yaw) * math.cos(pitch), math.cos(yaw) * math.cos(pitch), -math.sin(pitch)])
    r0 = np.array([math.cos(yaw), -math.sin(yaw), 0.0])
    d0 = np.cross(f, r0)
    r = math.cos(roll) * r0 + math.sin(roll) * d0
    d = -math.sin(roll) * r0 + math.cos(roll) * d0
    return np.stack([r, d, f], axis=1)


def _aim(scene: _Scene, target: np.ndarray, rng: np.random.Generator, *, tactile: bool) -> None:
    v = target - scene.eye
    yaw = math.atan2(v[0], v[1])
    pitch = math.atan2(-v[2], math.hypot(v[0], v[1]))
    if tactile:
        # People look at what they handle, but the hands sit low in the view.
        pitch = pitch * rng.uniform(0.78, 0.98) + rng.normal(0.0, math.radians(2.0))
        yaw += rng.normal(0.0, math.radians(4.0))
    else:
        # The gaze ray passes near the object; head and eyes need not align exactly.
        pitch += rng.normal(0.0, math.radians(2.0))
        yaw += rng.normal(0.0, math.radians(2.0))
    scene.pitch = float(np.clip(pitch, 0.0, math.radians(60.0)))
    scene.yaw = float(yaw)
    scene.roll = float(np.clip(rng.normal(0.0, math.radians(3.0)), -math.radians(8.0), math.radians(8.0)))
    scene.R = _camera_rotation(scene.yaw, scene.pitch, scene.roll)


def _body_point(scene: _Scene, side: float, right: float, forward: float, up: float) -> np.ndarray:
    return scene.eye + np.array([side * right, forward, up])


def _arm(scene: _Scene, side: str, palm: np.ndarray, axes: np.ndarray, skin: int, sleeve: int, forearm: int) -> _Hand:
    """Add a hand (palm, fingers, thumb), a forearm and an upper arm."""
    s = 1.0 if side == "right" else -1.0
    w, a, u = axes[:, 0], axes[:, 1], axes[:, 2]
    scene.add(_ELL, palm, (0.042, 0.017, 0.05), skin, axes=axes, obj=_HAND)
    fingers = _frame_from(u + 0.6 * a, a - 0.4 * u)
    scene.add(_ELL, palm + 0.055 * u + 0.014 * a, (0.04, 0.014, 0.04), skin, axes=fingers, obj=_HAND)
    thumb = _frame_from(u + a - s * 0.5 * w, a)
    scene.add(_ELL, palm - s * 0.038 * w + 0.018 * a + 0.01 * u, (0.012, 0.012, 0.032), skin, axes=thumb, obj=_HAND)
    wrist = palm - 0.06 * u
    shoulder = _body_point(scene, s, 0.2, -0.1, -0.27)
    anchor = _body_point(scene, s, 0.24, -0.02, -0.6)
    elbow = wrist + _unit(anchor - wrist) * 0.27
    fa = _frame_from(elbow - wrist, np.array([0.0, 0.0, 1.0]))
    scene.add(_ELL, (wrist + elbow) / 2.0, (0.036, 0.032, 0.15), forearm, axes=fa, obj=_HAND)
    up_len = float(np.linalg.norm(shoulder - elbow))
    ua = _frame_from(shoulder - elbow, np.array([1.0, 0.0, 0.0]))
    scene.add(_ELL, (shoulder + elbow) / 2.0, (0.046, 0.044, up_len / 2.0 + 0.02), sleeve, axes=ua, obj=_HAND)
    return _Hand(side, palm, [(wrist, elbow), (elbow, shoulder)])


def _grasp_pose(scene: _Scene, obj: _Candidate, side: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Palm centre and axes (w, a, u) for a hand touching the object."""
    s = 1.0 if side == "right" else -1.0
    c = obj.centre
    ext = (obj.hi - obj.lo) / 2.0
    body = scene.eye + np.array([s * 0.2, 0.0, -0.5])
    toward = body - c
    toward[2] = 0.0
    toward = _unit(toward)
    if _KINDS[obj.name].flat and obj.resting:
        # Hand on top, near the edge closest to the body.
        reach = min(ext[0], ext[1]) * rng.uniform(0.2, 0.6)
        palm = c + toward * reach
        palm[2] = obj.hi[2] + 0.019
        fwd = _unit(-toward + rng.normal(0.0, 0.15, 3) * np.array([1, 1, 0]))
        return palm, _frame_from(fwd, np.array([0.0, 0.0, -1.0]))
    # Side grasp on the main body (the first part; the rim of a held flat
    # object): the palm faces it from the wearer's side.
    body_part = obj.parts[0]
    bc = obj.pos + obj.rot @ np.asarray(body_part.centre)
    ang = s * rng.uniform(0.5, 1.1)
    side_dir = _rot_z(ang) @ toward
    radius = max(body_part.size[0], body_part.size[1])
    if body_part.shape == _BOX:
        radius *= 0.9
    palm = bc + side_dir * (radius + 0.018)
    palm[2] = bc[2] + rng.uniform(-0.25, 0.1) * body_part.size[2]
    # Fingers point away from the body along the object's side, a little upwards.
    fwd = _unit(np.array([0.0, 0.0, 0.3]) - toward)
    return palm, _frame_from(fwd, -side_dir)


def _rest_pose(scene: _Scene, side: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
    """Palm centre and axes for an idle hand resting on a surface near the body."""
    if not scene.rests:
        return None
    s = 1.0 if side == "right" else -1.0
    surf = scene.rests[int(rng.integers(len(scene.rests)))]
    x = s * rng.uniform(0.12, 0.32)
    if not surf.x0 <= x <= surf.x1:
        x = float(np.clip(x, surf.x0, surf.x1))
    palm = np.array([x, rng.uniform(surf.y0 + 0.07, max(surf.y0 + 0.08, surf.y1)), surf.z + 0.019])
    fwd = _rot_z(-s * rng.uniform(0.1, 0.5)) @ np.array([0.0, 1.0, 0.0])
    return palm, _frame_from(fwd, np.array([0.0, 0.0, -1.0]))


def _build_scene(activity: str, rng: np.random.Generator, *, tactile: bool) -> _Scene | None:
    """Sample one configuration; None when the action-object could not be placed."""
    spec = _ACTIVITY_SPECS[activity]
    scene = _Scene()
    scene.seated = bool(rng.random() < spec.seated_prob)
    eye_h = rng.uniform(*(_SEATED_EYE if scene.seated else _STANDING_EYE))
    scene.eye = np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.04, 0.04), eye_h])
    spec.layout(scene, rng, scene.seated)
    scene.kind = "tactile" if tactile else "visual"

    # 1. The action-object.
    kinds = spec.tactile_kinds if tactile else spec.visual_kinds
    action: _Candidate | None = None
    for _ in range(6):
        name = str(kinds[int(rng.integers(len(kinds)))])
        colour, colour2 = _object_colours(name, rng)

        def ok_action(c: _Candidate) -> bool:
            v = c.centre - scene.eye
            d = float(np.linalg.norm(v))
            bearing = abs(math.atan2(v[0], v[1]))
            if tactile:
                return 0.12 < v[1] and abs(v[0]) < 0.45 and d < 1.05
            return 0.7 <= d <= VISUAL_RANGE_M - 0.06 and bearing < math.radians(45.0)

        action = _sample_on(scene.surfaces, name, colour, colour2, rng, ok_action, tries=40)
        if action is not None:
            break
    if action is None:
        return None
    if tactile:
        d = float(np.linalg.norm(action.centre - scene.eye))
        if d > ARM_REACH_M - 0.08 or rng.random() < 0.25:
            # Held: the object leaves its surface towards the wearer.
            target = rng.uniform(0.42, min(ARM_REACH_M - 0.08, d - 0.02)) if d > 0.46 else d
            shift = (action.centre - scene.eye) * (target / d - 1.0)
            tilt = _KINDS[name].tilt
            rot = _rot_x(rng.uniform(-tilt, tilt)) @ _rot_y(rng.uniform(-tilt, tilt) * 0.5) @ action.rot
            # Rotate about the box centre so the centre stays put.
            centre = action.centre + shift
            pos = centre + rot @ action.rot.T @ (action.pos - action.centre)
            action = _make_candidate(name, colour, colour2, action.parts, rot, pos, resting=False)
    scene.action = _commit(scene, action)
    act_obj = scene.objects[scene.action]

    # 2. Where the wearer looks.
    _aim(scene, act_obj.centre + rng.normal(0.0, 0.03 if tactile else 0.01, 3), rng, tactile=tactile)

    # 3. Hands.
    skin_rgb = _jitter(_SKIN_TONES[int(rng.integers(len(_SKIN_TONES)))], rng, 0.05)
    skin = scene.material(_Mat(skin_rgb, spec=0.1))
    sleeve_rgb = _random_colour(rng, sat=(0.1, 0.7), val=(0.2, 0.8))
    sleeve = scene.material(_Mat(sleeve_rgb, _darker(sleeve_rgb, 0.8), _FABRIC, 150.0))
    forearm = skin if rng.random() < 0.6 else sleeve
    if tactile:
        main = "right" if rng.random() < (0.8 if act_obj.centre[0] > -0.1 else 0.3) else "left"
        other = "left" if main == "right" else "right"
        palm, axes = _grasp_pose(scene, action, main, rng)
        scene.hands.append(_arm(scene, main, palm, axes, skin, sleeve, forearm))
        if _KINDS[name].two_hands and rng.random() < 0.6:
            palm, axes = _grasp_pose(scene, action, other, rng)
            scene.hands.append(_arm(scene, other, palm, axes, skin, sleeve, forearm))
        elif rng.random() < 0.5:
            pose = _rest_pose(scene, other, rng)
            if pose is not None and _point_box_distance(pose[0], act_obj.lo, act_obj.hi) > _IDLE_CLEARANCE:
                scene.hands.append(_arm(scene, other, pose[0], pose[1], skin, sleeve, forearm))
    else:
        for side in ("left", "right"):
            if rng.random() < 0.35:
                pose = _rest_pose(scene, side, rng)
                if pose is not None and _point_box_distance(pose[0], act_obj.lo, act_obj.hi) > _IDLE_CLEARANCE:
                    scene.hands.append(_arm(scene, side, pose[0], pose[1], skin, sleeve, forearm))

    # 4. Distractors.
    gaze = scene.R[:, 2]
    act_perp = _ray_distance(scene.eye, gaze, act_obj.centre)

    def ok_distractor(c: _Candidate, *, far_only: bool = False) -> bool:
        los = np.array([o.lo for o in scene.objects])
        his = np.array([o.hi for o in scene.objects])
        if np.any(np.all((c.lo < his + 0.005) & (c.hi > los - 0.005), axis=1)):
            return False
        # Keep a gap around the action-object (a lifted object leaves its spot free,
        # but a distractor right under it would look stacked).
        if np.all((c.lo < act_obj.hi + 0.04) & (c.hi > act_obj.lo - 0.04)):
            return False
        radius = float(np.max(c.hi - c.lo)) / 2.0
        for h in scene.hands:
            if _point_box_distance(h.palm, c.lo, c.hi) < _IDLE_CLEARANCE + 0.03:
                return False
            for a, b in h.segments:
                if _segment_distance(c.centre, a, b) < radius + 0.06:
                    return False
        v = c.centre - scene.eye
        d = float(np.linalg.norm(v))
        if far_only and d < ARM_REACH_M + 0.1:
            return False
        if d <= VISUAL_RANGE_M + 0.05 and np.dot(v, gaze) > 0:
            if _ray_distance(scene.eye, gaze, c.centre) < act_perp + _VISUAL_MARGIN:
                return False
        return True

    # Objects of the action-object's kind, often the same colour, elsewhere.
    n_same = int(rng.integers(1, 3))
    for _ in range(n_same):
        if rng.random() < 0.6:
            c1, c2 = act_obj.colour, action.colour2
        else:
            c1, c2 = _object_colours(name, rng)
        cand = _sample_on(scene.surfaces, name, c1, c2, rng, lambda c: ok_distractor(c, far_only=True), tries=25)
        if cand is not None:
            _commit(scene, cand)
            scene.same_kind += 1
    n_other = int(rng.integers(spec.n_distractors[0], spec.n_distractors[1] + 1)) if spec.n_distractors[1] else 0
    for _ in range(n_other):
        dname = str(spec.distractor_kinds[int(rng.integers(len(spec.distractor_kinds)))])
        c1, c2 = _object_colours(dname, rng)
        cand = _sample_on(scene.surfaces, dname, c1, c2, rng, ok_distractor, tries=12)
        if cand is not None:
            _commit(scene, cand)
            if dname == name:
                scene.same_kind += 1
    if spec.shelf_fill:
        _fill_shelves(scene, rng, ok_distractor, name)
    if spec.garments:
        _fill_rack(scene, rng, ok_distractor)

    ld = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.6, 0.2), 1.0])
    scene.light = _unit(ld)
    return scene


def _fill_shelves(scene: _Scene, rng: np.random.Generator, accept, action_name: str) -> None:
    """Line shelf rows with facings of products (groups of the same kind and colour)."""
    for surf in scene.surfaces:
        if not surf.row:
            continue
        x = surf.x0 + rng.uniform(0.0, 0.05)
        while x < surf.x1 - 0.05:
            name = str(_SHELF_PRODUCTS[int(rng.integers(len(_SHELF_PRODUCTS)))])
            c1, c2 = _object_colours(name, rng)
            parts = _KINDS[name].build(c1, c2)
            corners = _corners(parts)
            for _ in range(int(rng.integers(1, 5))):
                rot = _rot_z(rng.normal(0.0, 0.06))
                lo, hi = _local_extent(corners, rot)
                if x - lo[0] + hi[0] > surf.x1:
                    break
                pos = np.array([x - lo[0], surf.y0 - lo[1] + rng.uniform(0.005, 0.03), surf.z])
                cand = _make_candidate(name, c1, c2, parts, rot, pos, corners=corners)
                if accept(cand):
                    _commit(scene, cand)
                    if name == action_name:
                        scene.same_kind += 1
                x = pos[0] + hi[0] + rng.uniform(0.004, 0.02)
            if rng.random() < 0.12:
                x += rng.uniform(0.05, 0.2)


def _fill_rack(scene: _Scene, rng: np.random.Generator, accept) -> None:
    rails = [s for s in scene.surfaces if s.hang]
    for surf in rails:
        y = surf.y0
        c1, c2 = _object_colours("garment", rng)
        parts = _KINDS["garment"].build(c1, c2)
        while y < surf.y1:
            if rng.random() < 0.3:
                c1, c2 = _object_colours("garment", rng)
                parts = _KINDS["garment"].build(c1, c2)
            rot = _rot_z(rng.normal(0.0, 0.05))
            lo, hi = _local_extent(_corners(parts), rot)
            cand = _make_candidate("garment", c1, c2, parts, rot, np.array([surf.x0, y, surf.z - hi[2]]))
            if accept(cand):
                _commit(scene, cand)
            y += rng.uniform(0.06, 0.1)


def _ray_distance(origin: np.ndarray, direction: np.ndarray, p: np.ndarray) -> float:
    v = p - origin
    return float(np.linalg.norm(v - np.dot(v, direction) * direction))


def _resolve_ground_truth(scene: _Scene) -> tuple[str, int] | None:
    """Apply the module's ground-truth rule to the 3D configuration.

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


# ---------------------------------------------------------------------------
# Ray casting
# ---------------------------------------------------------------------------


@dataclass
class _Cast:
    t: np.ndarray  # (H, W) z-depth, inf where nothing is hit
    pid: np.ndarray  # (H, W) primitive index, -1 where nothing is hit
    obj: np.ndarray  # (H, W) object id, -1 background, -2 hands
    K: np.ndarray  # (3, 3) intrinsics used
    us: np.ndarray  # (W,) normalised image x of each column
    vs: np.ndarray  # (H,) normalised image y of each row


# Each hitter takes the camera centre ``o`` (3,) and the ray direction
# components ``d`` (three (h, w) arrays) in the primitive's local frame, and
# returns the ray parameter of the first hit (inf on a miss). Because the
# directions have camera z = 1, the ray parameter is the z-depth.


def _t_box(o, d, e):
    for k in range(3):
        inv = 1.0 / d[k]
        t1 = (-e[k] - o[k]) * inv
        t2 = (e[k] - o[k]) * inv
        if k == 0:
            t_near = np.minimum(t1, t2)
            t_far = np.maximum(t1, t2)
        else:
            np.maximum(t_near, np.minimum(t1, t2), out=t_near)
            np.minimum(t_far, np.maximum(t1, t2), out=t_far)
    return np.where((t_near <= t_far) & (t_near > _NEAR), t_near, np.inf)


def _t_room(o, d, e):
    for k in range(3):
        inv = 1.0 / d[k]
        t_exit = np.maximum((-e[k] - o[k]) * inv, (e[k] - o[k]) * inv)
        t = t_exit if k == 0 else np.minimum(t, t_exit)
    return np.where(t > _NEAR, t, np.inf)


def _t_ellipsoid(o, d, radii):
    os_ = o / radii
    dx, dy, dz = d[0] / radii[0], d[1] / radii[1], d[2] / radii[2]
    a = dx * dx + dy * dy + dz * dz
    b = 2.0 * (os_[0] * dx + os_[1] * dy + os_[2] * dz)
    c = float(os_ @ os_) - 1.0
    disc = b * b - 4.0 * a * c
    t = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
    return np.where((disc >= 0.0) & (t > _NEAR), t, np.inf)


def _t_cylinder(o, d, size):
    r, hz = size[0], size[2]
    dx, dy, dz = d
    a = dx * dx + dy * dy
    b = 2.0 * (o[0] * dx + o[1] * dy)
    c = o[0] * o[0] + o[1] * o[1] - r * r
    disc = b * b - 4.0 * a * c
    t_side = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
    ok = (disc >= 0.0) & (np.abs(o[2] + t_side * dz) <= hz) & (t_side > _NEAR)
    t = np.where(ok, t_side, np.inf)
    if abs(o[2]) > hz:  # the camera sees one cap
        cap = hz if o[2] > 0 else -hz
        t_cap = (cap - o[2]) / dz
        px = o[0] + t_cap * dx
        py = o[1] + t_cap * dy
        ok_cap = (px * px + py * py <= r * r) & (t_cap > _NEAR)
        t = np.where(ok_cap & (t_cap < t), t_cap, t)
    return t


_HITTERS = {_ROOM: _t_room, _BOX: _t_box, _CYL: _t_cylinder, _ELL: _t_ellipsoid}

def _windows(centres, axes, sizes, eye, R, K, width, height) -> np.ndarray:
    """(P, 4) pixel rectangles (v0, v1, u0, u1) containing the projections of oriented boxes.

    Boxes reaching behind the camera get the whole image; empty rectangles
    have ``v0 >= v1`` or ``u0 >= u1``.
    """
    corners = centres[:, None, :] + np.einsum("kc,pc,pjc->pkj", _BOX_SIGNS, sizes, axes)
    cam = (corners - eye) @ R
    z = cam[..., 2]
    behind = np.any(z < 0.05, axis=1)
    zs = np.where(z < 0.05, 1.0, z)
    u = K[0, 0] * cam[..., 0] / zs + K[0, 2]
    v = K[1, 1] * cam[..., 1] / zs + K[1, 2]
    out = np.empty((len(centres), 4), dtype=np.int64)
    out[:, 0] = np.clip(np.floor(v.min(axis=1)) - 1, 0, height)
    out[:, 1] = np.clip(np.ceil(v.max(axis=1)) + 2, 0, height)
    out[:, 2] = np.clip(np.floor(u.min(axis=1)) - 1, 0, width)
    out[:, 3] = np.clip(np.ceil(u.max(axis=1)) + 2, 0, width)
    out[behind] = (0, height, 0, width)
    return out


@dataclass
class _PrimArrays:
    centres: np.ndarray
    axes: np.ndarray
    sizes: np.ndarray
    shapes: np.ndarray
    objs: np.ndarray


def _prim_arrays(scene: _Scene) -> _PrimArrays:
    """Primitive parameters as arrays, built once the scene is complete."""
    if scene.arrays is None or len(scene.arrays.shapes) != len(scene.prims):
        scene.arrays = _build_prim_arrays(scene)
    return scene.arrays


def _build_prim_arrays(scene: _Scene) -> _PrimArrays:
    return _PrimArrays(
        centres=np.array([p.centre for p in scene.prims]),
        axes=np.array([p.axes for p in scene.prims]),
        sizes=np.array([p.size for p in scene.prims]),
        shapes=np.array([p.shape for p in scene.prims]),
        objs=np.array([p.obj for p in scene.prims] + [_BACKGROUND], dtype=np.int32),
    )


def _cast(scene: _Scene, K: np.ndarray, width: int, height: int) -> _Cast:
    """Z-buffer the scene: nearest primitive and its depth for every pixel."""
    us = (np.arange(width, dtype=np.float64) - K[0, 2]) / K[0, 0]
    vs = (np.arange(height, dtype=np.float64) - K[1, 2]) / K[1, 1]
    R = scene.R
    arr = _prim_arrays(scene)
    wins = _windows(arr.centres, arr.axes, arr.sizes, scene.eye, R, K, width, height)
    wins[arr.shapes == _ROOM] = (0, height, 0, width)
    t_buf = np.full((height, width), np.inf)
    pid = np.full((height, width), -1, dtype=np.int32)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for i in np.nonzero((wins[:, 0] < wins[:, 1]) & (wins[:, 2] < wins[:, 3]))[0]:
            prim = scene.prims[i]
            v0, v1, u0, u1 = (int(x) for x in wins[i])
            # Local direction of pixel (u, v) = us[u] * A[:, 0] + vs[v] * A[:, 1] + A[:, 2].
            A = prim.axes.T @ R
            uw, vw = us[u0:u1], vs[v0:v1]
            d = [(uw * A[k, 0] + A[k, 2])[None, :] + (vw * A[k, 1])[:, None] for k in range(3)]
            o = (scene.eye - prim.centre) @ prim.axes
            t = _HITTERS[prim.shape](o, d, prim.size)
            t_view = t_buf[v0:v1, u0:u1]
            closer = t < t_view
            np.copyto(t_view, t, where=closer)
            np.copyto(pid[v0:v1, u0:u1], i, where=closer)
    return _Cast(t_buf, pid, arr.objs[pid], K, us, vs)  # pid -1 picks the trailing background entry


def _wave(x: np.ndarray) -> np.ndarray:
    """Smooth periodic wave in [0, 1] with period 1 (cheaper than a sine)."""
    t = np.abs(x - np.floor(x) - 0.5) * 2.0
    return t * t * (3.0 - 2.0 * t)


def _hash2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pseudo-random value in [0, 1] for each pair of integer cell coordinates."""
    h = (a.astype(np.int64) * 73856093) ^ (b.astype(np.int64) * 19349663)
    return (h & 1023) / 1023.0


def _albedo(
    mats: list[_Mat],
    mat: np.ndarray,
    local: list[np.ndarray],
    n_local: list[np.ndarray],
    points: np.ndarray,
    normal: list[np.ndarray],
    size: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Surface colour (3, n) and specular weight (n,) at the hit points.

    Vectors come as per-component rows; each texture gathers only the rows it
    needs at its own pixels (1-D integer gathers are much cheaper than masks).
    """
    rgb = np.array([m.rgb for m in mats]).T
    rgb2 = np.array([m.rgb2 for m in mats]).T
    tex_of = np.array([m.tex for m in mats])
    tex = tex_of[mat]
    scale = np.array([m.scale for m in mats])
    spec = np.array([m.spec for m in mats])[mat]
    col = [rgb[k][mat] for k in range(3)]
    for kind in np.unique(tex_of[np.unique(mat)]):
        if kind == _PLAIN:
            continue
        idx = np.flatnonzero(tex == kind)
        m = mat[idx]
        sc = scale[m]
        factor = None  # multiply the base colour
        blend = None  # (weight, colour 2): mix towards the second colour
        if kind == _WOOD:  # grain lines along the longer horizontal axis, slightly wavy
            lx, ly, lz = (local[k][idx] for k in range(3))
            x_long = size[0][idx] >= size[1][idx]
            along = np.where(x_long, lx, ly)
            across = np.where(x_long, ly, lx)
            wobble = 0.006 * _wave(along * 1.1) + 0.002 * _wave(along * 5.0 + lz * 6.0)
            g = _wave(sc * (across + lz * 0.3 + wobble) / (2.0 * math.pi))
            g *= g
            blend = g * g
        elif kind == _LABEL:  # a band around the middle and a thin stripe above it
            zr = local[2][idx] / np.maximum(size[2][idx], 1e-6)
            side = np.abs(n_local[2][idx]) < 0.5
            blend = ((np.abs(zr) < 0.45) & side).astype(np.float64)
            factor = 1.0 - 0.4 * ((np.abs(zr - 0.65) < 0.06) & side)
        elif kind == _SCREEN:  # a lit picture on the front face inside a bezel
            s0, s1, s2 = (np.maximum(size[k][idx], 1e-6) for k in range(3))
            xr = np.abs(local[0][idx]) / s0
            zr = local[2][idx] / s2
            front = (n_local[1][idx] < -0.5) & (xr < 0.93) & (np.abs(zr) < 0.88)
            # Flat screens (phones) show it on top.
            front |= (s2 < 0.01) & (n_local[2][idx] > 0.5) & (xr < 0.93) & (np.abs(local[1][idx]) / s1 < 0.9)
            glow = 0.6 + 0.4 * _wave(zr + xr * 0.5)
            blend = front.astype(np.float64)
            c2 = [0.3 + 0.7 * rgb2[k][m] * glow for k in range(3)]
        elif kind == _PAPER:  # faint printed lines within margins
            lx, ly = local[0][idx], local[1][idx]
            yy = ly * sc
            line = ((yy - np.floor(yy)) < 0.35) & (np.abs(lx) < 0.8 * size[0][idx])
            line &= (np.abs(ly) < 0.85 * size[1][idx]) & (n_local[2][idx] > 0.5)
            blend = 0.4 * line
            factor = 1.0 - 0.4 * line
        elif kind == _KEYS:  # a grid of dark gaps on the top face
            ax = local[0][idx] * sc
            ay = local[1][idx] * sc
            gap = ((ax - np.floor(ax)) < 0.18) | ((ay - np.floor(ay)) < 0.18)
            blend = (gap & (n_local[2][idx] > 0.5)).astype(np.float64)
        elif kind == _TILES:  # world-aligned squares with grout, each a slightly different shade
            px, py, pz = (points[k][idx] for k in range(3))
            horizontal = np.abs(normal[2][idx]) > 0.5
            a = np.where(horizontal | (np.abs(normal[1][idx]) > 0.5), px, py) / sc
            b = np.where(horizontal, py, pz) / sc
            fa, fb = np.floor(a), np.floor(b)
            factor = 0.88 + 0.24 * _hash2(fa, fb)
            blend = (((a - fa) < 0.035) | ((b - fb) < 0.035)).astype(np.float64)
        elif kind == _FABRIC:  # a fine weave
            px, py, pz = (points[k][idx] for k in range(3))
            f = 0.5 / math.pi
            factor = 0.93 + 0.07 * (2.0 * _wave(px * sc * f) - 1.0) * (2.0 * _wave((py + pz) * sc * f) - 1.0)
        if kind != _SCREEN:
            c2 = [rgb2[k][m] for k in range(3)]
        for k in range(3):
            c = col[k][idx]
            if factor is not None:
                c = c * factor
            if blend is not None:
                c = c + (c2[k] - c) * blend
            col[k][idx] = c
    return np.stack(col), spec


@dataclass
class _Surfels:
    """Shading inputs for the hit pixels; vectors are (3, N)."""

    flat: np.ndarray | slice  # flat pixel indices (a full slice when every pixel is hit)
    points: np.ndarray  # world
    normal: np.ndarray  # world, unit
    view: np.ndarray  # unit ray directions
    albedo: np.ndarray
    spec: np.ndarray  # (N,)


def _surfels(scene: _Scene, cast: _Cast) -> _Surfels:
    """Hit points, normals and surface colours, all pixels at once."""
    h, w = cast.t.shape
    flat_pid = cast.pid.ravel()
    if flat_pid.min() >= 0:  # the room is closed, so this is the usual case
        flat: np.ndarray | slice = slice(None)
        pid = flat_pid
        cols = np.tile(np.arange(w), h)
        rows = np.repeat(np.arange(h), w)
    else:
        flat = np.flatnonzero(flat_pid >= 0)
        pid = flat_pid[flat]
        rows, cols = np.divmod(flat, w)
    R = scene.R
    ucol, vrow = cast.us[cols], cast.vs[rows]
    dirs = np.stack([R[i, 0] * ucol + R[i, 1] * vrow + R[i, 2] for i in range(3)])
    points = scene.eye[:, None] + cast.t.ravel()[flat] * dirs
    arr = _prim_arrays(scene)
    # Per-pixel primitive frames: a[3 * i + k] is axes[i, k] (world component i of local axis k).
    a = np.take(arr.axes.reshape(-1, 9).T, pid, axis=1)
    rel = points - np.take(arr.centres.T, pid, axis=1)
    size = np.take(arr.sizes.T, pid, axis=1)
    shape = arr.shapes[pid]
    local = [a[k] * rel[0] + a[3 + k] * rel[1] + a[6 + k] * rel[2] for k in range(3)]
    # Boxes and rooms (computed everywhere, overwritten below for curved shapes):
    # the normal is along the axis where the point is relatively furthest out.
    r = [np.abs(local[k]) / size[k] for k in range(3)]
    ax0 = (r[0] >= r[1]) & (r[0] >= r[2])
    ax1 = ~ax0 & (r[1] >= r[2])
    ax2 = ~(ax0 | ax1)
    is_room = shape == _ROOM
    flip = 1.0 - 2.0 * is_room  # room normals point inwards
    n_local = [ax * np.sign(lk) * flip for ax, lk in zip((ax0, ax1, ax2), local)]
    face = is_room * (ax0 * (local[0] > 0) + ax1 * (2 + (local[1] > 0)) + ax2 * (4 + (local[2] > 0)))
    cyl = np.flatnonzero(shape == _CYL)
    if len(cyl):
        p0, p1, p2 = (local[k][cyl] for k in range(3))
        radial = np.hypot(p0, p1)
        on_cap = np.abs(np.abs(p2) - size[2][cyl]) < np.abs(radial - size[0][cyl])
        safe = np.maximum(radial, 1e-9)
        n_local[0][cyl] = np.where(on_cap, 0.0, p0 / safe)
        n_local[1][cyl] = np.where(on_cap, 0.0, p1 / safe)
        n_local[2][cyl] = np.where(on_cap, np.sign(p2), 0.0)
    ell = np.flatnonzero(shape == _ELL)
    if len(ell):
        nl = [local[k][ell] / size[k][ell] ** 2 for k in range(3)]
        norm = np.maximum(np.sqrt(nl[0] ** 2 + nl[1] ** 2 + nl[2] ** 2), 1e-12)
        for k in range(3):
            n_local[k][ell] = nl[k] / norm
    normal = [a[3 * i] * n_local[0] + a[3 * i + 1] * n_local[1] + a[3 * i + 2] * n_local[2] for i in range(3)]
    prim_mat = np.array([p.material for p in scene.prims], dtype=np.int64)
    mat = prim_mat[pid] + face
    albedo, spec = _albedo(scene.materials, mat, local, n_local, points, normal, size)
    view = dirs / np.sqrt(dirs[0] ** 2 + dirs[1] ** 2 + dirs[2] ** 2)
    return _Surfels(flat, points, np.stack(normal), view, albedo, spec)


# ---------------------------------------------------------------------------
# Shading
# ---------------------------------------------------------------------------


def _shade(scene: _Scene, cast: _Cast, rng: np.random.Generator) -> np.ndarray:
    h, w = cast.t.shape
    sf = _surfels(scene, cast)
    nx, ny, nz = sf.normal
    vx, vy, vz = sf.view
    L = scene.light
    # Lambert shading with a key light, a weak headlight and a little specular.
    lam = np.clip(L[0] * nx + L[1] * ny + L[2] * nz, 0.0, None)
    head = np.abs(nx * vx + ny * vy + nz * vz)
    hx, hy, hz = L[0] - vx, L[1] - vy, L[2] - vz
    hn = np.maximum(np.sqrt(hx * hx + hy * hy + hz * hz), 1e-9)
    c = np.clip((nx * hx + ny * hy + nz * hz) / hn, 0.0, 1.0)
    c8 = (c * c) ** 2
    c8 *= c8
    sp = c8 * c8 * c8 * sf.spec * 0.6  # (n . h)^24
    light = (0.36 + 0.52 * lam + 0.16 * head) * _contact_shadows(scene, cast, sf)
    light /= 1.0 + 0.04 * np.maximum(cast.t.ravel()[sf.flat] - 1.0, 0.0)  # gentle fall-off with distance
    # Exposure and white balance per frame, low-frequency mottling per pixel.
    gain = rng.uniform(0.9, 1.08) * (1.0 + rng.uniform(-0.03, 0.03, 3))
    lo = rng.normal(0.0, 1.0, (max(2, h // 24 + 2), max(2, w // 24 + 2))).astype(np.float32)
    mottle = 1.0 + 0.02 * cv2.resize(lo, (w, h), interpolation=cv2.INTER_CUBIC).ravel()[sf.flat]
    planes = np.zeros((3, h * w), dtype=np.float32)
    planes[:, sf.flat] = (sf.albedo * (light * mottle) + sp) * (255.0 * gain)[:, None]
    img = np.ascontiguousarray(planes.reshape(3, h, w).transpose(1, 2, 0))
    # Lens blur and sensor noise (mostly luminance, a little per channel).
    img = cv2.GaussianBlur(np.clip(img, 0.0, 255.0), (0, 0), sigmaX=0.6)
    img += (1.8 * rng.standard_normal((h, w), dtype=np.float32))[..., None]
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _contact_shadows(scene: _Scene, cast: _Cast, sf: _Surfels) -> np.ndarray:
    """(N,) light factors: soft dark blobs under resting objects (cheap ambient occlusion)."""
    h, w = cast.t.shape
    resting = [(oid, o) for oid, o in enumerate(scene.objects) if o.resting]
    if not resting:
        return np.ones(sf.points.shape[1])
    lo = np.array([o.lo for _, o in resting])
    hi = np.array([o.hi for _, o in resting])
    centres = np.stack([(lo[:, 0] + hi[:, 0]) / 2.0, (lo[:, 1] + hi[:, 1]) / 2.0, lo[:, 2]], axis=1)
    rad = np.maximum(hi[:, 0] - lo[:, 0], hi[:, 1] - lo[:, 1]) / 2.0
    sizes = np.stack([rad * 1.8, rad * 1.8, np.full_like(rad, 0.01)], axis=1)
    wins = _windows(centres, np.broadcast_to(np.eye(3), (len(rad), 3, 3)), sizes, scene.eye, scene.R, cast.K, w, h)
    visible = np.nonzero((wins[:, 0] < wins[:, 1]) & (wins[:, 2] < wins[:, 3]))[0]
    if len(visible) == 0:
        return np.ones(sf.points.shape[1])
    px, py, pz = (np.full(h * w, np.inf) for _ in range(3))
    px[sf.flat], py[sf.flat] = sf.points[0], sf.points[1]
    pz[sf.flat] = np.where(sf.normal[2] > 0.8, sf.points[2], np.inf)  # only up-facing surfaces
    px, py, pz = px.reshape(h, w), py.reshape(h, w), pz.reshape(h, w)
    shade = np.ones((h, w))
    with np.errstate(invalid="ignore", over="ignore"):
        for k in visible:
            oid = resting[k][0]
            v0, v1, u0, u1 = (int(x) for x in wins[k])
            win = np.s_[v0:v1, u0:u1]
            d2 = ((px[win] - centres[k, 0]) ** 2 + (py[win] - centres[k, 1]) ** 2) / (rad[k] * rad[k])
            near = (np.abs(pz[win] - centres[k, 2]) < 0.012) & (cast.obj[win] != oid)
            blob = np.maximum(1.0 - 0.5 * d2, 0.0)
            shade[win] *= 1.0 - 0.45 * (blob * blob) * near
    return shade.ravel()[sf.flat]


def _fallback_mask(scene: _Scene, K: np.ndarray, width: int, height: int) -> np.ndarray:
    mask = np.zeros((height, width), dtype=bool)
    c = (scene.objects[scene.action].centre - scene.eye) @ scene.R
    u = int(np.clip(round(K[0, 0] * c[0] / c[2] + K[0, 2]), 0, width - 1))
    v = int(np.clip(round(K[1, 1] * c[1] / c[2] + K[1, 2]), 0, height - 1))
    mask[v, u] = True
    return mask


def _meta(scene: _Scene, activity: str, index: int, seed: int, attempt: int, mask: np.ndarray, cast: _Cast) -> dict:
    obj = scene.objects[scene.action]
    up = scene.R.T @ np.array([0.0, 0.0, 1.0])
    touching = sorted(
        {h.side for h in scene.hands if _point_box_distance(h.palm, obj.lo, obj.hi) <= CONTACT_M}
    ) if scene.kind == "tactile" else []
    return {
        "activity": activity,
        "index": int(index),
        "seed": int(seed),
        "attempt": int(attempt),
        "camera_height_m": round(float(scene.eye[2]), 4),
        "pitch_deg": round(math.degrees(scene.pitch), 4),
        "roll_deg": round(math.degrees(scene.roll), 4),
        "yaw_deg": round(math.degrees(scene.yaw), 4),
        "up_cam": [float(x) for x in up],
        "hfov_deg": HFOV_DEG,
        "seated": bool(scene.seated),
        "kind": scene.kind,
        "object": obj.name,
        "object_distance_m": round(float(np.linalg.norm(obj.centre - scene.eye)), 4),
        "object_height_m": round(float(obj.centre[2]), 4),
        "object_rgb": [round(float(x), 3) for x in obj.colour],
        "hands_touching": touching,
        "hands_visible": bool((cast.obj == _HAND).any()),
        "n_objects": len(scene.objects),
        "same_kind_distractors": int(scene.same_kind),
        "mask_fraction": round(float(mask.mean()), 6),
    }
