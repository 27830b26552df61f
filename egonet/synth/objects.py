"""Object kinds (mugs, pots, keyboards...) and placing objects on surfaces."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from egonet.synth.scene import (
    _BOX,
    _BOX_SIGNS,
    _CYL,
    _ELL,
    _FABRIC,
    _KEYS,
    _LABEL,
    _PAPER,
    _SCREEN,
    _WOOD,
    _darker,
    _jitter,
    _Mat,
    _Object,
    _Part,
    _random_colour,
    _rot_x,
    _rot_z,
    _Scene,
    _Surface,
)

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
