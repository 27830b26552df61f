"""Ray casting: the first primitive each pixel's ray hits, and its z-depth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from egonet.synth.scene import _BOX, _BOX_SIGNS, _CYL, _ELL, _ROOM, _prim_arrays, _Scene

_NEAR = 0.02  # ignore hits closer than this to the camera (m)


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
