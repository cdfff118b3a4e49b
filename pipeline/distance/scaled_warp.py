"""Fused warp kernels (float64) for the per-axis scaled sphere, cylinder and capsule fields.

Each kernel computes, per point, exactly what the numpy/torch code of
:mod:`pipeline.distance.primitive` computes (``SphereShape``, ``CylinderShape``, ``CapsuleShape``;
the formulas are stated there): phi, grad and closest point, with the ellipse/ellipsoid solve of
:mod:`pipeline.distance.ellipsoid_warp`. Inputs are coordinate columns (numpy, or torch on the
CPU or CUDA); results come back as columns of the same kind (torch: the input's dtype).

The ``*_world`` kernels also take the object poses (R_j, t_j), j < T, for numpy world points
x (N, 3), N = T K, point i at pose j = i // K (one pose: T = 1; one per frame: K links a frame):
per point p = R_j^T (x - t_j), the object-frame field, then grad = R_j g and closest = R_j c + t_j
(as :class:`pipeline.distance.field.ObjectField` does in numpy), so the poses cost no numpy pass
over the points. They run on the CPU (numpy points), one thread per pose looping over its K points:
the pose is loaded once and no point pays an index division.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import warp as wp

from pipeline.distance import ellipsoid_warp as ell
from pipeline.distance.ellipsoid import Ellipsoid
from pipeline.distance.warp_runtime import warp
from pipeline.xp import is_numpy

EPS = wp.constant(wp.float64(1e-9))  # pipeline.distance.primitive.EPS


vec7d = wp.types.vector(length=7, dtype=wp.float64)


@wp.func
def _pack(phi: wp.float64, g: wp.vec3d, c: wp.vec3d) -> vec7d:
    """(phi, grad, closest) as one vector."""
    return vec7d(phi, g[0], g[1], g[2], c[0], c[1], c[2])


@wp.func
def _write(out: wp.array2d(dtype=wp.float64), i: int, r: vec7d):
    for k in range(7):
        out[k, i] = r[k]


@wp.func
def _local(R: wp.mat33d, t: wp.vec3d, x: wp.vec3d) -> wp.vec3d:
    """p = R^T (x - t): a world point in the object frame."""
    return wp.transpose(R) * (x - t)


@wp.func
def _write_world(
    R: wp.mat33d,
    t: wp.vec3d,
    r: vec7d,
    i: int,
    phi: wp.array(dtype=wp.float64),
    grad: wp.array(dtype=wp.vec3d),
    closest: wp.array(dtype=wp.vec3d),
):
    """phi, grad = R g, closest = R c + t: an object-frame result back in the world."""
    phi[i] = r[0]
    grad[i] = R * wp.vec3d(r[1], r[2], r[3])
    closest[i] = R * wp.vec3d(r[4], r[5], r[6]) + t


@wp.func
def _section_closest(s: ell.Spec, p: wp.vec3d) -> wp.vec3d:
    """Closest point (qx, qy, 0) of the section's boundary to (x, y)."""
    return ell.closest(s, p)


@wp.func
def _section_normal(s: ell.Spec, p: wp.vec3d, q: wp.vec3d) -> wp.vec3d:
    """Outward unit normal (nx, ny, 0) at the boundary point q; a circle's is the radial unit."""
    if s.ng == 1:
        return ell.units(s, p, ell.reduce(s, p))
    return ell.normal(s, q)


@wp.func
def _section_inside(s: ell.Spec, p: wp.vec3d) -> bool:
    if s.ng == 1:
        return ell.reduce(s, p)[2] < s.b[2]
    return ell.inside(s, p)


@wp.func
def _sphere(e: ell.Spec, p: wp.vec3d) -> vec7d:
    """Ellipsoid: phi = |p - c|; grad = (p - c)/phi outside, the normal at c inside or on it."""
    c = ell.closest(e, p)
    d = p - c
    phi = wp.length(d)
    g = d * (wp.float64(1.0) / phi)
    if ell.inside(e, p) or phi <= EPS:
        g = ell.normal(e, c)
    return _pack(phi, g, c)


@wp.func
def _cylinder(sec: ell.Spec, h: wp.float64, p: wp.vec3d) -> vec7d:
    """Elliptic cylinder |z| <= h: section and axial clamp outside; inside, the nearer of side and cap."""
    pxy = wp.vec3d(p[0], p[1], wp.float64(0.0))
    q = _section_closest(sec, pxy)
    n = _section_normal(sec, pxy, q)
    c = wp.vec3d(q[0], q[1], wp.clamp(p[2], -h, h))
    if _section_inside(sec, pxy):
        c = wp.vec3d(p[0], p[1], c[2])
    d = p - c
    out_d = wp.length(d)
    side = wp.sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]))
    cap = h - wp.abs(p[2])
    sz = ell.sign(p[2])
    phi = out_d
    g = d * (wp.float64(1.0) / out_d)
    if out_d <= EPS:
        if side <= cap:
            phi = side
            g = wp.vec3d(n[0], n[1], wp.float64(0.0))
            c = wp.vec3d(q[0], q[1], c[2])
        else:
            phi = wp.abs(cap)
            g = wp.vec3d(wp.float64(0.0), wp.float64(0.0), sz)
            c = wp.vec3d(c[0], c[1], sz * h)
    return _pack(phi, g, c)


@wp.func
def _restricted_cap(cap: ell.Spec, pc: wp.vec3d, phi: wp.float64, c: wp.vec3d, h: wp.float64) -> wp.vec4d:
    """(phi, closest point in the capsule frame): the nearest normal point of the cap's upper half
    to pc (cap frame) where nearer than ``phi``, else (phi, c + h)."""
    y = ell.reduce(cap, pc)
    u = ell.units(cap, pc, y)
    best = phi
    bq = c
    for j in range(ell.normal_point_count(cap)):
        q = ell.normal_point(cap, y, u, j)
        d = wp.length(pc - q)
        if q[2] >= wp.float64(0.0) and d < best:
            best = d
            bq = q
    return wp.vec4d(best, bq[0], bq[1], bq[2] + h)


@wp.func
def _capsule(cap: ell.Spec, sec: ell.Spec, h: wp.float64, restricted: int, p0: wp.vec3d) -> vec7d:
    """Scaled capsule, folded to w = |z|, cap ellipsoid E centred at (0, 0, h).

    w >= h: the closest point of E (it lies on E's upper half, which holds the capsule's nearest
    point: below z = h a point of the solid is farther than its lift to z = h); outside the grad
    is (p - c)/phi, inside E the normal. w < h: the section's closest point at height w (the
    infinite elliptic cylinder holds the capsule); inside, the side unless (``restricted``: E's z
    semi-axis below the section's largest) a normal point of E's upper half is nearer."""
    sz = ell.sign(p0[2])
    p = wp.vec3d(p0[0], p0[1], wp.abs(p0[2]))
    w = p[2]
    phi = wp.float64(0.0)
    g = wp.vec3d()
    c = wp.vec3d()
    if w >= h:
        pc = wp.vec3d(p[0], p[1], w - h)
        e = ell.closest(cap, pc)
        c = wp.vec3d(e[0], e[1], e[2] + h)
        d = p - c
        phi = wp.length(d)
        g = d * (wp.float64(1.0) / phi)
        if ell.inside(cap, pc) or phi <= EPS:
            g = ell.normal(cap, e)
    else:
        pxy = wp.vec3d(p[0], p[1], wp.float64(0.0))
        q = _section_closest(sec, pxy)
        c = wp.vec3d(q[0], q[1], w)
        d = p - c
        phi = wp.length(d)
        g = d * (wp.float64(1.0) / phi)
        if _section_inside(sec, pxy) or phi <= EPS:
            n = _section_normal(sec, pxy, q)
            g = wp.vec3d(n[0], n[1], wp.float64(0.0))
            if restricted == 1 and h - w < phi:
                pc = wp.vec3d(p[0], p[1], w - h)
                r = _restricted_cap(cap, pc, phi, wp.vec3d(q[0], q[1], w - h), h)
                if r[0] < phi:
                    g = ell.normal(cap, wp.vec3d(r[1], r[2], r[3] - h))
                phi = r[0]
                c = wp.vec3d(r[1], r[2], r[3])
    return _pack(phi, wp.vec3d(g[0], g[1], sz * g[2]), wp.vec3d(c[0], c[1], sz * c[2]))


_F64 = wp.array(dtype=wp.float64)
_V3 = wp.array(dtype=wp.vec3d)
_M33 = wp.array(dtype=wp.mat33d)


@wp.kernel
def sphere_field(e: ell.Spec, x: _F64, y: _F64, z: _F64, out: wp.array2d(dtype=wp.float64)):
    i = wp.tid()
    _write(out, i, _sphere(e, wp.vec3d(x[i], y[i], z[i])))


@wp.kernel
def cylinder_field(sec: ell.Spec, h: wp.float64, x: _F64, y: _F64, z: _F64, out: wp.array2d(dtype=wp.float64)):
    i = wp.tid()
    _write(out, i, _cylinder(sec, h, wp.vec3d(x[i], y[i], z[i])))


@wp.kernel
def capsule_field(
    cap: ell.Spec,
    sec: ell.Spec,
    h: wp.float64,
    restricted: int,
    x: _F64,
    y: _F64,
    z: _F64,
    out: wp.array2d(dtype=wp.float64),
):
    i = wp.tid()
    _write(out, i, _capsule(cap, sec, h, restricted, wp.vec3d(x[i], y[i], z[i])))


@wp.kernel
def sphere_world(e: ell.Spec, R: _M33, t: _V3, k: int, x: _V3, phi: _F64, grad: _V3, closest: _V3):
    j = wp.tid()
    Rj = R[j]
    tj = t[j]
    for i in range(j * k, j * k + k):
        _write_world(Rj, tj, _sphere(e, _local(Rj, tj, x[i])), i, phi, grad, closest)


@wp.kernel
def cylinder_world(sec: ell.Spec, h: wp.float64, R: _M33, t: _V3, k: int, x: _V3, phi: _F64, grad: _V3, closest: _V3):
    j = wp.tid()
    Rj = R[j]
    tj = t[j]
    for i in range(j * k, j * k + k):
        _write_world(Rj, tj, _cylinder(sec, h, _local(Rj, tj, x[i])), i, phi, grad, closest)


@wp.kernel
def capsule_world(
    cap: ell.Spec,
    sec: ell.Spec,
    h: wp.float64,
    restricted: int,
    R: _M33,
    t: _V3,
    k: int,
    x: _V3,
    phi: _F64,
    grad: _V3,
    closest: _V3,
):
    j = wp.tid()
    Rj = R[j]
    tj = t[j]
    for i in range(j * k, j * k + k):
        _write_world(Rj, tj, _capsule(cap, sec, h, restricted, _local(Rj, tj, x[i])), i, phi, grad, closest)


@lru_cache(maxsize=64)
def _spec(axes: tuple[float, ...]) -> ell.Spec:
    return ell.spec(Ellipsoid(axes))


def _launch(kernel, args: list, x, y, z, xp):
    """Run ``kernel(*args, x, y, z, out)`` next to the columns; (phi, grad columns, closest columns)."""
    wp = warp()
    n = len(x)
    if is_numpy(xp):
        out = np.empty((7, n))
        cols = [wp.array(np.ascontiguousarray(a, dtype=np.float64), dtype=wp.float64, device="cpu") for a in (x, y, z)]
        o, device, stream = wp.array(out, dtype=wp.float64, copy=False, device="cpu"), "cpu", None
    else:
        out = xp.empty((7, n), dtype=xp.float64, device=x.device)
        cols = [wp.from_torch(a.to(xp.float64).contiguous()) for a in (x, y, z)]
        o, device = wp.from_torch(out), wp.device_from_torch(x.device)
        stream = wp.stream_from_torch(x.device) if x.device.type == "cuda" else None
    if n:
        wp.launch(kernel, dim=n, inputs=[*args, *cols], outputs=[o], device=device, stream=stream)
    if not is_numpy(xp):
        out = out.to(x.dtype)
    return out[0], (out[1], out[2], out[3]), (out[4], out[5], out[6])


def _launch_world(kernel, args: list, points: np.ndarray, R: np.ndarray, t: np.ndarray):
    """Run ``kernel(*args, R, t, K, points, phi, grad, closest)`` on the CPU for numpy world ``points`` (N, 3)
    at poses ``R`` (T, 3, 3), ``t`` (T, 3), N = T K: point i at pose i // K (one thread per pose)."""
    wp = warp()
    n, poses = len(points), len(R)
    if n % max(poses, 1):
        raise ValueError(f"{n} points do not split into {poses} poses")
    phi, grad, closest = np.empty(n), np.empty((n, 3)), np.empty((n, 3))
    if n:
        cols = [
            (R, wp.mat33d),
            (t, wp.vec3d),
            (points, wp.vec3d),
            (phi, wp.float64),
            (grad, wp.vec3d),
            (closest, wp.vec3d),
        ]
        R, t, pts, *outs = [
            wp.array(np.ascontiguousarray(a, dtype=np.float64), dtype=d, copy=False, device="cpu") for a, d in cols
        ]
        wp.launch(kernel, dim=poses, inputs=[*args, R, t, n // poses, pts], outputs=outs, device="cpu")
    return phi, grad, closest


def _cylinder_args(radii: tuple[float, float], half_length: float) -> list:
    return [_spec(radii), wp.float64(half_length)]


def _capsule_args(radii: tuple[float, float, float], half_length: float) -> list:
    """Cap ellipsoid, section ellipse, half-length, and ``restricted`` (E's z semi-axis below the section's largest)."""
    return [_spec(radii), _spec(radii[:2]), wp.float64(half_length), int(radii[2] < max(radii[:2]))]


def sphere(radii: tuple[float, float, float], x, y, z, xp):
    """The field of the ellipsoid with semi-axes ``radii``."""
    return _launch(sphere_field, [_spec(radii)], x, y, z, xp)


def cylinder(radii: tuple[float, float], half_length: float, x, y, z, xp):
    """The field of the cylinder along z with section radii ``radii`` and half-length ``half_length``."""
    return _launch(cylinder_field, _cylinder_args(radii, half_length), x, y, z, xp)


def capsule(radii: tuple[float, float, float], half_length: float, x, y, z, xp):
    """The field of the capsule along z: segment [-half_length, half_length], ball semi-axes ``radii``."""
    return _launch(capsule_field, _capsule_args(radii, half_length), x, y, z, xp)


def sphere_world_field(radii: tuple[float, float, float], points: np.ndarray, R: np.ndarray, t: np.ndarray):
    """:func:`sphere` at numpy world ``points`` (N, 3) for poses ``R`` (T, 3, 3), ``t`` (T, 3), point i at pose
    i // (N / T): (phi, grad, closest) world arrays."""
    return _launch_world(sphere_world, [_spec(radii)], points, R, t)


def cylinder_world_field(
    radii: tuple[float, float], half_length: float, points: np.ndarray, R: np.ndarray, t: np.ndarray
):
    """:func:`cylinder` at numpy world ``points`` for poses (R, t), as :func:`sphere_world_field`."""
    return _launch_world(cylinder_world, _cylinder_args(radii, half_length), points, R, t)


def capsule_world_field(
    radii: tuple[float, float, float], half_length: float, points: np.ndarray, R: np.ndarray, t: np.ndarray
):
    """:func:`capsule` at numpy world ``points`` for poses (R, t), as :func:`sphere_world_field`."""
    return _launch_world(capsule_world, _capsule_args(radii, half_length), points, R, t)
