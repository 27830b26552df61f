"""The scene description: primitives, materials, objects, surfaces, hands.

Also the small geometry and colour helpers every stage uses, and the scene's
primitives packed as arrays for the ray caster and the shader.
"""

from __future__ import annotations

import colorsys
import math
from dataclasses import dataclass, field

import numpy as np

# Primitive shapes.
_ROOM, _BOX, _CYL, _ELL = 0, 1, 2, 3
# Texture kinds.
_PLAIN, _TILES, _WOOD, _LABEL, _SCREEN, _PAPER, _FABRIC, _KEYS = range(8)

_HAND = -2  # object id of hand and arm primitives
_BACKGROUND = -1

# The eight corners of a box, as signs of its half extents.
_BOX_SIGNS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=np.float64)


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


# The primitives as arrays, cached on the scene for the ray caster and the shader.
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


def _ray_distance(origin: np.ndarray, direction: np.ndarray, p: np.ndarray) -> float:
    v = p - origin
    return float(np.linalg.norm(v - np.dot(v, direction) * direction))
