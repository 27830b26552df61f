"""Rendering a frame: :func:`render_frame`, :func:`render_activity`, :class:`SynthFrame`."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from egonet.errors import EgonetError
from egonet.synth.layouts import _ACTIVITY_SPECS, ACTIVITIES
from egonet.synth.raycast import _cast, _Cast
from egonet.synth.sampling import _build_scene
from egonet.synth.scene import _HAND, _point_box_distance, _Scene
from egonet.synth.shading import _shade
from egonet.synth.truth import CONTACT_M, _resolve_ground_truth

HFOV_DEG = 80.0
"""Horizontal field of view of the synthetic lens (square pixels)."""

_CHECK_WIDTH = 128  # resolution of the visibility check (pixels wide)
_CHECK_MIN_FRACTION = 0.0065  # visible area required at the check resolution
_MAX_ATTEMPTS = 40


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
        hands: ``(H, W)`` bool visible pixels of the wearer's hands and arms
            (sleeves included: one primitive group in the scene); often empty.
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
    hands: np.ndarray


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

    scene, attempt = _valid_scene(activity, index, seed=seed, width=width, height=height)
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
        hands=cast.obj == _HAND,
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


def _valid_scene(activity: str, index: int, *, seed: int, width: int, height: int) -> tuple[_Scene, int]:
    """The first sampled scene whose ground truth is clear and visible, and its attempt number.

    Only the aspect ratio of ``width`` and ``height`` matters: visibility is
    checked at ``_CHECK_WIDTH`` pixels wide, so the scene does not depend on
    the resolution.
    """
    act_id = ACTIVITIES.index(activity)
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
        return scene, attempt
    # Construction makes this unreachable in practice.
    raise RuntimeError(f"could not build a valid scene for {activity!r} frame {index}")  # pragma: no cover


# ---------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------


def _check_activity(activity: object) -> int:
    if not isinstance(activity, str) or activity not in ACTIVITIES:
        valid = ", ".join(repr(a) for a in ACTIVITIES)
        raise EgonetError(f"activity must be one of {valid}; got {activity!r}", field="activity")
    return ACTIVITIES.index(activity)


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _check_index(value: object, name: str) -> None:
    # Below 2**32 so each value is one word of the generator's seed.
    if not _is_int(value) or not 0 <= value < 2**32:
        raise EgonetError(f"{name} must be an integer in [0, 2**32); got {value!r}", field=name)


def _check_size(value: object, name: str) -> None:
    if not _is_int(value) or value <= 0:
        raise EgonetError(f"{name} must be an integer > 0 (pixels); got {value!r}", field=name)


# ---------------------------------------------------------------------------
# Mask fallback and metadata
# ---------------------------------------------------------------------------


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
