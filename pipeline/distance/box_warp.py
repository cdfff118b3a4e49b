"""Fused warp kernels (float64, CPU) for the box and for a union of boxes (the chair), with the pose.

Per point, exactly what :class:`pipeline.distance.primitive.BoxShape` and ``ChairShape`` compute
in numpy (the formulas are stated there), in the same operations and order:

* box with half-extents h at p: c = clip(p, -h, h), phi = |p - c| and grad = (p - c)/phi outside;
  on or inside the solid (phi <= EPS) the face of largest q = |p| - h (x before y before z on
  ties), grad = its outward axis (sign +1 at 0), c on that face, phi = |max q|;
* union of boxes (half-extents h_k, centres o_k): the part with the least box phi (``|q+|`` outside,
  ``-max q`` inside), the first on ties, then the full box field of that part at p - o_k, c + o_k.

Poses as in :mod:`pipeline.distance.scaled_warp` (``*_world`` kernels): world points x (N, 3),
N = T K, at poses (R_j, t_j), point i at pose i // K; p = R_j^T (x - t_j), then grad = R_j g and
closest = R_j c + t_j. One thread per pose looping over its K points.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import warp as wp

from pipeline.distance.ellipsoid_warp import sign
from pipeline.distance.scaled_warp import EPS, _launch_world, _local, _pack, _write_world, vec7d
from pipeline.distance.warp_runtime import warp

_F64 = wp.array(dtype=wp.float64)
_V3 = wp.array(dtype=wp.vec3d)
_M33 = wp.array(dtype=wp.mat33d)


@wp.func
def _box(h: wp.vec3d, p: wp.vec3d) -> vec7d:
    """Box field at p (box frame): phi, grad, closest (as ``distance_primitive._box``)."""
    c = wp.vec3d(wp.clamp(p[0], -h[0], h[0]), wp.clamp(p[1], -h[1], h[1]), wp.clamp(p[2], -h[2], h[2]))
    d = p - c
    out = wp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    if out > EPS:
        inv = wp.float64(1.0) / out
        return _pack(out, wp.vec3d(d[0] * inv, d[1] * inv, d[2] * inv), c)
    qx = wp.abs(p[0]) - h[0]
    qy = wp.abs(p[1]) - h[1]
    qz = wp.abs(p[2]) - h[2]
    depth = wp.abs(wp.max(wp.max(qx, qy), qz))
    z = wp.float64(0.0)
    if qx >= qy and qx >= qz:
        s = sign(p[0])
        return _pack(depth, wp.vec3d(s, z, z), wp.vec3d(s * h[0], c[1], c[2]))
    if qy >= qz:
        s = sign(p[1])
        return _pack(depth, wp.vec3d(z, s, z), wp.vec3d(c[0], s * h[1], c[2]))
    s = sign(p[2])
    return _pack(depth, wp.vec3d(z, z, s), wp.vec3d(c[0], c[1], s * h[2]))


@wp.func
def _box_phi(h: wp.vec3d, p: wp.vec3d) -> wp.float64:
    """phi only (as ``distance_primitive.box_phi``): |max(q, 0)| outside, -max q inside, q = |p| - h."""
    qx = wp.abs(p[0]) - h[0]
    qy = wp.abs(p[1]) - h[1]
    qz = wp.abs(p[2]) - h[2]
    z = wp.float64(0.0)
    ox = wp.max(qx, z)
    oy = wp.max(qy, z)
    oz = wp.max(qz, z)
    out = wp.sqrt(ox * ox + oy * oy + oz * oz)
    if out > z:
        return out
    return -wp.max(wp.max(qx, qy), qz)


@wp.func
def _boxes(half: _V3, centre: _V3, p: wp.vec3d) -> vec7d:
    """Union of boxes: the nearest part's box field (the first on ties), closest point back in the union's frame."""
    best = _box_phi(half[0], p - centre[0])
    part = int(0)  # noqa: UP018 - a warp dynamic variable (a bare 0 is a constant inside the loop)
    for k in range(1, half.shape[0]):
        phi = _box_phi(half[k], p - centre[k])
        if phi < best:
            best = phi
            part = k
    o = centre[part]
    r = _box(half[part], p - o)
    return vec7d(r[0], r[1], r[2], r[3], r[4] + o[0], r[5] + o[1], r[6] + o[2])


@wp.kernel
def box_world(h: wp.vec3d, R: _M33, t: _V3, k: int, x: _V3, phi: _F64, grad: _V3, closest: _V3):
    j = wp.tid()
    Rj = R[j]
    tj = t[j]
    for i in range(j * k, j * k + k):
        _write_world(Rj, tj, _box(h, _local(Rj, tj, x[i])), i, phi, grad, closest)


@wp.kernel
def boxes_world(half: _V3, centre: _V3, R: _M33, t: _V3, k: int, x: _V3, phi: _F64, grad: _V3, closest: _V3):
    j = wp.tid()
    Rj = R[j]
    tj = t[j]
    for i in range(j * k, j * k + k):
        _write_world(Rj, tj, _boxes(half, centre, _local(Rj, tj, x[i])), i, phi, grad, closest)


@lru_cache(maxsize=16)
def _parts(parts: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...]):
    """(half-extents, centres) of the parts as CPU warp arrays."""
    table = np.array([[*h, *o] for h, o in parts], dtype=np.float64).reshape(-1, 6)
    wp = warp()
    return (
        wp.array(np.ascontiguousarray(table[:, :3]), dtype=wp.vec3d, device="cpu"),
        wp.array(np.ascontiguousarray(table[:, 3:]), dtype=wp.vec3d, device="cpu"),
    )


def box_world_field(half: tuple[float, float, float], points: np.ndarray, R: np.ndarray, t: np.ndarray):
    """The box field at numpy world ``points`` (N, 3) for poses ``R`` (T, 3, 3), ``t`` (T, 3), point i at pose
    i // (N / T): (phi, grad, closest) world arrays."""
    return _launch_world(box_world, [wp.vec3d(*half)], points, R, t)


def boxes_world_field(
    parts: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...],
    points: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
):
    """The field of the union of boxes ``parts`` ((half-extents, centre), ...; at least one) at numpy world
    ``points`` for poses (R, t), as :func:`box_world_field`."""
    if not parts:
        raise ValueError("a union of boxes needs at least one part")
    return _launch_world(boxes_world, list(_parts(parts)), points, R, t)
