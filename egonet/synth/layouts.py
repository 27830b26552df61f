"""Activity layouts: rooms, furniture and the surfaces objects stand on.

:data:`ACTIVITIES` and, per activity, its layout, posture and object mix.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from egonet.synth.objects import _METAL
from egonet.synth.scene import (
    _BOX,
    _CYL,
    _ELL,
    _FABRIC,
    _TILES,
    _WOOD,
    _darker,
    _jitter,
    _Mat,
    _random_colour,
    _rot_x,
    _Scene,
    _Surface,
)

ACTIVITIES: tuple[str, ...] = (
    "cooking",
    "dining",
    "grocery",
    "hotel",
    "desk work",
    "shopping",
    "dishwashing",
)


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
# Layouts
# ---------------------------------------------------------------------------


def _kitchen_room(scene: _Scene, rng, xl, xr, back, *, tile: tuple[float, float, float], tile_scale: float) -> None:
    """A kitchen's room: the back wall (y+) tiled with ``tile`` squares of ``tile_scale`` metres."""
    scene.room(
        (xl, -rng.uniform(1.5, 2.5), 0.0),
        (xr, back, rng.uniform(2.4, 2.7)),
        [
            _wall(rng),
            _wall(rng),
            _wall(rng),
            _Mat(tile, _darker(tile, 0.8), _TILES, tile_scale),
            _floor(rng, "tiles"),
            _ceiling(),
        ],
    )


def _counter_with_cabinets(scene: _Scene, rng, x0, x1, y0, y1, top_z, top_mat: int, door_mat: int) -> None:
    scene.block((x0, y0 + 0.04, 0.0), (x1, y1, top_z - 0.04), door_mat)
    scene.block((x0, y0 + 0.02, 0.0), (x1, y0 + 0.05, 0.1), scene.material(_Mat((0.15, 0.15, 0.15))))
    scene.block((x0, y0, top_z - 0.04), (x1, y1, top_z), top_mat)


def _layout_cooking(scene: _Scene, rng: np.random.Generator, seated: bool) -> None:
    top = rng.uniform(0.88, 0.94)
    front = rng.uniform(0.22, 0.3)
    back = front + rng.uniform(0.58, 0.66)
    xl, xr = -rng.uniform(1.6, 2.4), rng.uniform(1.6, 2.4)
    _kitchen_room(scene, rng, xl, xr, back, tile=_jitter((0.85, 0.85, 0.82), rng, 0.1), tile_scale=0.15)
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
    _kitchen_room(scene, rng, xl, xr, back, tile=_jitter((0.8, 0.85, 0.88), rng, 0.08), tile_scale=0.12)
    stone = _jitter(rng.choice([(0.85, 0.84, 0.8), (0.3, 0.3, 0.32), (0.55, 0.5, 0.45)]), rng, 0.08)
    top_mat = scene.material(_Mat(stone, _darker(stone, 0.9), _FABRIC, 200.0, spec=0.2))
    door = scene.material(_Mat(_jitter(rng.choice([(0.9, 0.9, 0.88), (0.4, 0.5, 0.45)]), rng, 0.08)))
    steel = scene.material(_Mat((0.6, 0.62, 0.64), spec=0.6))
    sink = _counter_with_sink(scene, rng, xl, xr, front, back, top, top_mat, door, steel)
    # Window above the sink.
    scene.block((sink.xc - 0.5, back - 0.01, 1.2), (sink.xc + 0.5, back, 2.0), scene.material(_Mat((0.85, 0.9, 0.97))))
    upper_z = rng.uniform(1.45, 1.55)
    scene.block((xl, back - 0.33, upper_z), (sink.xc - 0.6, back, upper_z + 0.7), door)
    scene.block((sink.xc + 0.6, back - 0.33, upper_z), (xr, back, upper_z + 0.7), door)
    dish_kinds = frozenset({"plate", "bowl", "cup", "mug", "pan", "glass", "pot", "sponge"})
    scene.surfaces.extend(
        [
            _Surface(
                sink.x0 + 0.01, sink.x1 - 0.01, sink.y0 + 0.01, sink.y1 - 0.01, sink.bottom + 0.005, kinds=dish_kinds
            ),
            _Surface(xl + 0.05, sink.x0 - 0.03, front + 0.03, back - 0.05, top),
            _Surface(sink.x1 + 0.03, xr - 0.05, front + 0.03, back - 0.05, top),
        ]
    )
    scene.rests.append(_Surface(-0.35, 0.35, front, front + 0.07, top))


@dataclass(frozen=True)
class _Sink:
    """A sink's opening in the worktop (x0..x1, y0..y1, centred at x = xc) and its basin floor."""

    xc: float
    x0: float
    x1: float
    y0: float
    y1: float
    bottom: float


def _counter_with_sink(
    scene: _Scene, rng, xl, xr, front, back, top, top_mat: int, door_mat: int, steel_mat: int
) -> _Sink:
    """Cabinets, a worktop around a sink opening, a steel basin and a tap."""
    sxc = rng.uniform(-0.2, 0.2)
    sx0, sx1 = sxc - rng.uniform(0.25, 0.32), sxc + rng.uniform(0.25, 0.32)
    sy0, sy1 = front + 0.08, front + rng.uniform(0.44, 0.5)
    bottom = top - rng.uniform(0.18, 0.22)
    scene.block((xl, front + 0.02, 0.0), (xr, back, bottom), door_mat)  # cabinets below
    for lo, hi in (
        ((xl, front, bottom), (sx0, back, top)),
        ((sx1, front, bottom), (xr, back, top)),
        ((sx0, front, bottom), (sx1, sy0, top)),
        ((sx0, sy1, bottom), (sx1, back, top)),
    ):
        scene.block(lo, hi, top_mat)
    # Steel liners make the basin walls and floor.
    scene.block((sx0, sy0, bottom), (sx1, sy1, bottom + 0.005), steel_mat)
    scene.block((sx0, sy0, bottom), (sx0 + 0.006, sy1, top - 0.002), steel_mat)
    scene.block((sx1 - 0.006, sy0, bottom), (sx1, sy1, top - 0.002), steel_mat)
    scene.block((sx0, sy0, bottom), (sx1, sy0 + 0.006, top - 0.002), steel_mat)
    scene.block((sx0, sy1 - 0.006, bottom), (sx1, sy1, top - 0.002), steel_mat)
    # Tap.
    tx = sxc + rng.uniform(-0.05, 0.05)
    scene.add(_CYL, (tx, sy1 + 0.06, top + 0.13), (0.018, 0.018, 0.13), steel_mat)
    scene.add(_BOX, (tx, sy1 - 0.04, top + 0.25), (0.014, 0.1, 0.012), steel_mat)
    return _Sink(xc=sxc, x0=sx0, x1=sx1, y0=sy0, y1=sy1, bottom=bottom)


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
