"""Shading: textures, normals, lighting, contact shadows and sensor noise."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from egonet.synth.raycast import _Cast, _windows
from egonet.synth.scene import (
    _CYL,
    _ELL,
    _FABRIC,
    _KEYS,
    _LABEL,
    _PAPER,
    _PLAIN,
    _ROOM,
    _SCREEN,
    _TILES,
    _WOOD,
    _Mat,
    _prim_arrays,
    _Scene,
)


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
    A texture multiplies the base colour by a factor, mixes it towards the
    material's second colour by a weight, or both.
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
        c2 = [rgb2[k][m] for k in range(3)]
        if kind == _WOOD:
            blend = _wood_grain(idx, sc, local, size)
        elif kind == _LABEL:
            factor, blend = _label_band(idx, local, n_local, size)
        elif kind == _SCREEN:
            blend, glow = _screen(idx, local, n_local, size)
            c2 = [0.3 + 0.7 * rgb2[k][m] * glow for k in range(3)]
        elif kind == _PAPER:
            factor, blend = _printed_lines(idx, sc, local, n_local, size)
        elif kind == _KEYS:
            blend = _key_gaps(idx, sc, local, n_local)
        elif kind == _TILES:
            factor, blend = _tiles(idx, sc, points, normal)
        elif kind == _FABRIC:
            factor = _weave(idx, sc, points)
        for k in range(3):
            c = col[k][idx]
            if factor is not None:
                c = c * factor
            if blend is not None:
                c = c + (c2[k] - c) * blend
            col[k][idx] = c
    return np.stack(col), spec


# The textures. Each takes the indices ``idx`` of its hit points and, where it
# uses one, their materials' scale ``sc``, and gathers the rows it needs.


def _wood_grain(idx: np.ndarray, sc: np.ndarray, local: list[np.ndarray], size: np.ndarray) -> np.ndarray:
    """Grain lines along the longer horizontal axis, slightly wavy: the weight of colour 2."""
    lx, ly, lz = (local[k][idx] for k in range(3))
    x_long = size[0][idx] >= size[1][idx]
    along = np.where(x_long, lx, ly)
    across = np.where(x_long, ly, lx)
    wobble = 0.006 * _wave(along * 1.1) + 0.002 * _wave(along * 5.0 + lz * 6.0)
    g = _wave(sc * (across + lz * 0.3 + wobble) / (2.0 * math.pi))
    g *= g
    return g * g


def _label_band(
    idx: np.ndarray, local: list[np.ndarray], n_local: list[np.ndarray], size: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A band around the middle and a thin dark stripe above it: (factor, weight)."""
    zr = local[2][idx] / np.maximum(size[2][idx], 1e-6)
    side = np.abs(n_local[2][idx]) < 0.5
    blend = ((np.abs(zr) < 0.45) & side).astype(np.float64)
    factor = 1.0 - 0.4 * ((np.abs(zr - 0.65) < 0.06) & side)
    return factor, blend


def _screen(
    idx: np.ndarray, local: list[np.ndarray], n_local: list[np.ndarray], size: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A lit picture on the front face inside a bezel: (weight, glow of colour 2)."""
    s0, s1, s2 = (np.maximum(size[k][idx], 1e-6) for k in range(3))
    xr = np.abs(local[0][idx]) / s0
    zr = local[2][idx] / s2
    front = (n_local[1][idx] < -0.5) & (xr < 0.93) & (np.abs(zr) < 0.88)
    # Flat screens (phones) show it on top.
    front |= (s2 < 0.01) & (n_local[2][idx] > 0.5) & (xr < 0.93) & (np.abs(local[1][idx]) / s1 < 0.9)
    glow = 0.6 + 0.4 * _wave(zr + xr * 0.5)
    return front.astype(np.float64), glow


def _printed_lines(
    idx: np.ndarray, sc: np.ndarray, local: list[np.ndarray], n_local: list[np.ndarray], size: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Faint printed lines within margins on the top face: (factor, weight)."""
    lx, ly = local[0][idx], local[1][idx]
    yy = ly * sc
    line = ((yy - np.floor(yy)) < 0.35) & (np.abs(lx) < 0.8 * size[0][idx])
    line &= (np.abs(ly) < 0.85 * size[1][idx]) & (n_local[2][idx] > 0.5)
    return 1.0 - 0.4 * line, 0.4 * line


def _key_gaps(idx: np.ndarray, sc: np.ndarray, local: list[np.ndarray], n_local: list[np.ndarray]) -> np.ndarray:
    """A grid of dark gaps on the top face: the weight of colour 2."""
    ax = local[0][idx] * sc
    ay = local[1][idx] * sc
    gap = ((ax - np.floor(ax)) < 0.18) | ((ay - np.floor(ay)) < 0.18)
    return (gap & (n_local[2][idx] > 0.5)).astype(np.float64)


def _tiles(
    idx: np.ndarray, sc: np.ndarray, points: np.ndarray, normal: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """World-aligned squares with grout, each a slightly different shade: (factor, weight)."""
    px, py, pz = (points[k][idx] for k in range(3))
    horizontal = np.abs(normal[2][idx]) > 0.5
    a = np.where(horizontal | (np.abs(normal[1][idx]) > 0.5), px, py) / sc
    b = np.where(horizontal, py, pz) / sc
    fa, fb = np.floor(a), np.floor(b)
    factor = 0.88 + 0.24 * _hash2(fa, fb)
    blend = (((a - fa) < 0.035) | ((b - fb) < 0.035)).astype(np.float64)
    return factor, blend


def _weave(idx: np.ndarray, sc: np.ndarray, points: np.ndarray) -> np.ndarray:
    """A fine weave: the factor."""
    px, py, pz = (points[k][idx] for k in range(3))
    f = 0.5 / math.pi
    return 0.93 + 0.07 * (2.0 * _wave(px * sc * f) - 1.0) * (2.0 * _wave((py + pz) * sc * f) - 1.0)


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
