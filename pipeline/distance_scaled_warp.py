"""Fused warp kernels (float64) for the per-axis scaled sphere, cylinder and capsule fields.

Each kernel computes, per point, exactly what the numpy/torch code of
:mod:`pipeline.distance_primitive` computes (``SphereShape``, ``CylinderShape``, ``CapsuleShape``;
the formulas are stated there): phi, grad and closest point, with the ellipse/ellipsoid solve of
:mod:`pipeline.distance_ellipsoid_warp`. Inputs are coordinate columns (numpy, or torch on the
CPU or CUDA); results come back as columns of the same kind (torch: the input's dtype).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import warp as wp

from pipeline import distance_ellipsoid_warp as ell
from pipeline.array_ns import is_numpy
from pipeline.distance_ellipsoid import Ellipsoid
from pipeline.warp_runtime import warp

EPS = wp.constant(wp.float64(1e-9))  # pipeline.distance_primitive.EPS


@wp.func
def _write(out: wp.array2d(dtype=wp.float64), i: int, phi: wp.float64, g: wp.vec3d, c: wp.vec3d):
    out[0, i] = phi
    for k in range(3):
        out[1 + k, i] = g[k]
        out[4 + k, i] = c[k]


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


@wp.kernel
def sphere_field(e: ell.Spec, x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)):
    """Ellipsoid: phi = |p - c|; grad = (p - c)/phi outside, the normal at c inside or on it."""
    i = wp.tid()
    p = wp.vec3d(x[i], y[i], z[i])
    c = ell.closest(e, p)
    d = p - c
    phi = wp.length(d)
    g = d * (wp.float64(1.0) / phi)
    if ell.inside(e, p) or phi <= EPS:
        g = ell.normal(e, c)
    _write(out, i, phi, g, c)


@wp.kernel
def cylinder_field(
    sec: ell.Spec, h: wp.float64, x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)
):
    """Elliptic cylinder |z| <= h: section and axial clamp outside; inside, the nearer of side and cap."""
    i = wp.tid()
    p = wp.vec3d(x[i], y[i], z[i])
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
    _write(out, i, phi, g, c)


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


@wp.kernel
def capsule_field(
    cap: ell.Spec,
    sec: ell.Spec,
    h: wp.float64,
    restricted: int,
    x: wp.array(dtype=wp.float64),
    y: wp.array(dtype=wp.float64),
    z: wp.array(dtype=wp.float64),
    out: wp.array2d(dtype=wp.float64),
):
    """Scaled capsule, folded to w = |z|, cap ellipsoid E centred at (0, 0, h).

    w >= h: the closest point of E (it lies on E's upper half, which holds the capsule's nearest
    point: below z = h a point of the solid is farther than its lift to z = h); outside the grad
    is (p - c)/phi, inside E the normal. w < h: the section's closest point at height w (the
    infinite elliptic cylinder holds the capsule); inside, the side unless (``restricted``: E's z
    semi-axis below the section's largest) a normal point of E's upper half is nearer."""
    i = wp.tid()
    sz = ell.sign(z[i])
    p = wp.vec3d(x[i], y[i], wp.abs(z[i]))
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
    _write(out, i, phi, wp.vec3d(g[0], g[1], sz * g[2]), wp.vec3d(c[0], c[1], sz * c[2]))


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


def sphere(radii: tuple[float, float, float], x, y, z, xp):
    """The field of the ellipsoid with semi-axes ``radii``."""
    return _launch(sphere_field, [_spec(radii)], x, y, z, xp)


def cylinder(radii: tuple[float, float], half_length: float, x, y, z, xp):
    """The field of the cylinder along z with section radii ``radii`` and half-length ``half_length``."""
    return _launch(cylinder_field, [_spec(radii), wp.float64(half_length)], x, y, z, xp)


def capsule(radii: tuple[float, float, float], half_length: float, x, y, z, xp):
    """The field of the capsule along z: segment [-half_length, half_length], ball semi-axes ``radii``."""
    restricted = int(radii[2] < max(radii[:2]))
    return _launch(capsule_field, [_spec(radii), _spec(radii[:2]), wp.float64(half_length), restricted], x, y, z, xp)
