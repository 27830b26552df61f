"""Scene sampling: the action-object, where the wearer looks, hands, distractors."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from egonet.synth.layouts import _ACTIVITY_SPECS, _SHELF_PRODUCTS, _Activity
from egonet.synth.objects import (
    _KINDS,
    _Candidate,
    _commit,
    _corners,
    _local_extent,
    _make_candidate,
    _object_colours,
    _sample_on,
)
from egonet.synth.scene import (
    _BOX,
    _ELL,
    _FABRIC,
    _HAND,
    _darker,
    _frame_from,
    _Hand,
    _jitter,
    _Mat,
    _point_box_distance,
    _random_colour,
    _ray_distance,
    _rot_x,
    _rot_y,
    _rot_z,
    _Scene,
    _segment_distance,
    _unit,
)
from egonet.synth.truth import ARM_REACH_M, VISUAL_RANGE_M, _VISUAL_MARGIN

_IDLE_CLEARANCE = 0.12  # palms of hands that touch nothing stay this far from objects
_STANDING_EYE = (1.52, 1.72)
_SKIN_TONES = ((0.87, 0.68, 0.55), (0.75, 0.55, 0.42), (0.55, 0.38, 0.27), (0.36, 0.24, 0.17), (0.93, 0.76, 0.64))
_SEATED_EYE = (1.12, 1.28)


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
    action = _place_action(scene, spec, rng, tactile=tactile)
    if action is None:
        return None
    scene.action = _commit(scene, action)
    act_obj = scene.objects[scene.action]

    # 2. Where the wearer looks.
    _aim(scene, act_obj.centre + rng.normal(0.0, 0.03 if tactile else 0.01, 3), rng, tactile=tactile)

    # 3. Hands.
    _add_hands(scene, action, rng, tactile=tactile)

    # 4. Distractors.
    _add_distractors(scene, spec, action, rng)

    ld = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.6, 0.2), 1.0])
    scene.light = _unit(ld)
    return scene


def _place_action(scene: _Scene, spec: _Activity, rng: np.random.Generator, *, tactile: bool) -> _Candidate | None:
    """Pose the action-object: on a surface, or (tactile, sometimes) lifted towards the wearer."""
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
    return action


def _add_hands(scene: _Scene, action: _Candidate, rng: np.random.Generator, *, tactile: bool) -> None:
    """Hands that grasp the action-object (tactile) and idle hands resting on a surface."""
    act_obj = scene.objects[scene.action]
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
        if _KINDS[action.name].two_hands and rng.random() < 0.6:
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


def _distractor_check(scene: _Scene) -> Callable[..., bool]:
    """The test a distractor's pose must pass, against the scene as it grows.

    A distractor overlaps no object, keeps clear of the action-object, hands
    and arms, and lies further from the gaze ray than the action-object (by
    ``_VISUAL_MARGIN``) when it could compete as a visual action-object;
    ``far_only`` also keeps it out of reach.
    """
    act_obj = scene.objects[scene.action]
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

    return ok_distractor


def _add_distractors(scene: _Scene, spec: _Activity, action: _Candidate, rng: np.random.Generator) -> None:
    """Objects of the action-object's kind out of reach, other objects, filled shelves and racks."""
    act_obj = scene.objects[scene.action]
    name = action.name
    ok_distractor = _distractor_check(scene)
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
