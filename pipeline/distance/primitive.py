"""Exact distance fields of the primitives (box, sphere, cylinder, capsule) and of a Chair, in the object frame.

For a point p (object frame, per-axis scale already applied to the shape):

    phi(p)  = min_{c on the surface} |p - c|      (unsigned; c is the closest surface point)
    grad(p) = (p - c) / phi                      outside the solid,
            = outward unit normal at c           inside the solid and on the surface (phi <= EPS).

Every shape's ``local(x, y, z, xp)`` takes coordinate columns and returns
``(phi, (gx, gy, gz), (cx, cy, cz))``, written once for numpy and torch (``xp``).

Closed forms: box (clamp; inside, the nearest face), sphere (radial), cylinder (radial and
axial clamp; inside, the nearer of side and cap), capsule (distance to the axis segment minus
the radius). A per-axis scale keeps a box a box but turns a sphere into an ellipsoid, a
cylinder into an elliptic cylinder and a capsule into an elliptic cylinder with ellipsoidal
caps; those use :mod:`pipeline.distance.ellipsoid` (exact to rounding), run point by point in the
fused float64 warp kernels of :mod:`pipeline.distance.scaled_warp` (numpy, torch CPU or CUDA; the
numpy/torch ``local_xp`` where warp cannot run, and as the kernels' reference). The box and the chair
(union of boxes) are numpy/torch in ``local``; their ``world`` (a pose per frame, numpy points) runs the
same math fused with the pose in :mod:`pipeline.distance.box_warp`. For the scaled capsule
(fold z to z >= 0, cap ellipsoid E centred at +H):

* outside: the solid is convex and symmetric, so the nearer of the projections onto the
  cylinder part (ellipse section x [-H, H]) and onto E;
* inside, z >= H: the closest point of E (it lies on the upper half, which is the boundary);
* inside, z < H: the side (the section's closest point at the same z) unless the cap is
  nearer; the cap's normal points above its centre plane seen from below it exist only
  when the z semi-axis is not the largest, and are found among all of E's normal points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.distance.ellipsoid import Ellipsoid
from pipeline.distance.warp_runtime import runs_on
from pipeline.geometry import Chair, Primitive
from pipeline.xp import nonzero

EPS = 1e-9  # m: a point this close to the surface takes the outward normal as its direction


def _sign(c):
    """+1 or -1, with +1 at zero."""
    return 1.0 - 2.0 * (c < 0)


def _norm3(x, y, z, xp):
    return xp.sqrt(x * x + y * y + z * z)


def _isotropic(r) -> bool:
    return max(r) - min(r) <= 1e-12 * max(r)


@dataclass(frozen=True)
class _Section:
    """The cross-section x-y of a cylinder or capsule: a circle or an axis-aligned ellipse."""

    radii: tuple[float, float]

    def closest(self, x, y, xp):
        """(qx, qy, nx, ny, inside): closest boundary point, outward normal there, strictly inside."""
        if _isotropic(self.radii):
            return _circle_closest(x, y, self.radii[0], xp)
        e = Ellipsoid(self.radii)
        qx, qy = e.closest([x, y], xp)
        nx, ny = e.normal([qx, qy], xp)
        return qx, qy, nx, ny, e.inside([x, y])


def _circle_closest(x, y, r, xp):
    """:meth:`_Section.closest` for a circle of radius ``r`` (a scalar, or an array broadcasting with ``x``)."""
    rho = xp.sqrt(x * x + y * y)
    safe = xp.where(rho > 0, rho, 1.0)
    ux, uy = xp.where(rho > 0, x / safe, 1.0), y / safe
    return r * ux, r * uy, ux, uy, rho < r


def cylinder_local(x, y, z, r, h, xp):
    """``(phi, grad, closest)`` of circular cylinders along z, radius ``r`` and half-length ``h`` (scalars, or arrays
    broadcasting with ``x``: a batch of cylinders of their own sizes), at points in their frames; numpy or torch
    (:meth:`CylinderShape.local_xp`'s circular case; the mjlab backend's batch of drawn cylinders)."""
    return _cylinder_field(x, y, z, _circle_closest(x, y, r, xp), h, xp)


def _cylinder_field(x, y, z, section, h, xp):
    """The field of a cylinder along z of half-length ``h`` given its section's :meth:`_Section.closest`."""
    qx, qy, nx, ny, in_sec = section
    cx, cy, cz = xp.where(in_sec, x, qx), xp.where(in_sec, y, qy), xp.clip(z, -h, h)
    dx, dy, dz = x - cx, y - cy, z - cz
    out = _norm3(dx, dy, dz, xp)
    solid = out <= EPS
    side = xp.sqrt((x - qx) ** 2 + (y - qy) ** 2)
    cap = h - abs(z)
    use_side = solid & (side <= cap)
    use_cap = solid & ~use_side
    inv = 1.0 / xp.where(solid, 1.0, out)
    sz = _sign(z)
    g = (
        xp.where(use_side, nx, xp.where(use_cap, 0.0, dx * inv)),
        xp.where(use_side, ny, xp.where(use_cap, 0.0, dy * inv)),
        xp.where(use_side, 0.0, xp.where(use_cap, sz, dz * inv)),
    )
    c = (xp.where(use_side, qx, cx), xp.where(use_side, qy, cy), xp.where(use_cap, sz * h, cz))
    phi = xp.where(use_side, side, xp.where(use_cap, abs(cap), out))
    return phi, g, c


def box_local(x, y, z, hx, hy, hz, xp):
    """Box field; half-extents are floats or per-point arrays."""
    cx, cy, cz = xp.clip(x, -hx, hx), xp.clip(y, -hy, hy), xp.clip(z, -hz, hz)
    dx, dy, dz = x - cx, y - cy, z - cz
    out = _norm3(dx, dy, dz, xp)
    solid = out <= EPS
    qx, qy, qz = abs(x) - hx, abs(y) - hy, abs(z) - hz
    ax = (qx >= qy) & (qx >= qz)
    ay = ~ax & (qy >= qz)
    az = ~ax & ~ay
    inv = 1.0 / xp.where(solid, 1.0, out)
    sx, sy, sz = _sign(x), _sign(y), _sign(z)
    g = (
        xp.where(solid, ax * sx, dx * inv),
        xp.where(solid, ay * sy, dy * inv),
        xp.where(solid, az * sz, dz * inv),
    )
    c = (xp.where(solid & ax, sx * hx, cx), xp.where(solid & ay, sy * hy, cy), xp.where(solid & az, sz * hz, cz))
    depth = abs(xp.maximum(xp.maximum(qx, qy), qz))
    return xp.where(solid, depth, out), g, c


def nearest_box(x, y, z, boxes, xp):
    """Index of the nearest of ``boxes`` at each point (the first on ties): ``(half-extents, centre)`` per box, each
    three components that are floats or arrays broadcasting with ``x`` (one union, or a batch of unions)."""
    best = part = None
    for k, (h, c) in enumerate(boxes):
        phi = box_phi(x - c[0], y - c[1], z - c[2], h[0], h[1], h[2], xp)
        if best is None:
            best, part = phi, 0 * (phi > 0)
            continue
        near = phi < best
        best, part = xp.where(near, phi, best), xp.where(near, k, part)
    return part


def box_phi(x, y, z, hx, hy, hz, xp):
    """phi only: |outside distance| or inside depth."""
    qx, qy, qz = abs(x) - hx, abs(y) - hy, abs(z) - hz
    ox, oy, oz = xp.clip(qx, 0.0, None), xp.clip(qy, 0.0, None), xp.clip(qz, 0.0, None)
    out = _norm3(ox, oy, oz, xp)
    return xp.where(out > 0, out, -xp.maximum(xp.maximum(qx, qy), qz))


@dataclass(frozen=True)
class BoxShape:
    """Box with half-extents ``half`` (scale applied)."""

    half: tuple[float, float, float]

    def local(self, x, y, z, xp):
        return box_local(x, y, z, *self.half, xp)

    def world(self, points, R, t):
        """As :meth:`SphereShape.world`: the fused kernel of :mod:`pipeline.distance.box_warp`."""
        from pipeline.distance import box_warp as distance_box_warp

        return distance_box_warp.box_world_field(self.half, points, R, t)


@dataclass(frozen=True)
class SphereShape:
    """Sphere of radius r scaled per axis: an ellipsoid with semi-axes ``radii``."""

    radii: tuple[float, float, float]

    def local(self, x, y, z, xp):
        if _isotropic(self.radii):
            r = self.radii[0]
            rho = _norm3(x, y, z, xp)
            safe = xp.where(rho > 0, rho, 1.0)
            u = (xp.where(rho > 0, x / safe, 1.0), y / safe, z / safe)
            return abs(rho - r), u, (r * u[0], r * u[1], r * u[2])
        if runs_on(x):
            from pipeline.distance import scaled_warp as distance_scaled_warp

            return distance_scaled_warp.sphere(self.radii, x, y, z, xp)
        return self.local_xp(x, y, z, xp)

    def world(self, points, R, t):
        """The field at numpy world ``points`` (N, 3) for poses ``R`` (T, 3, 3), ``t`` (T, 3), point i at pose
        i // (N / T), in one warp kernel; None (round) where not fused."""
        if _isotropic(self.radii):
            return None
        from pipeline.distance import scaled_warp as distance_scaled_warp

        return distance_scaled_warp.sphere_world_field(self.radii, points, R, t)

    def local_xp(self, x, y, z, xp):
        """The ellipsoid's field in numpy/torch (where warp cannot run; the kernel's reference)."""
        e = Ellipsoid(self.radii)
        c = e.closest([x, y, z], xp)
        d = (x - c[0], y - c[1], z - c[2])
        phi = _norm3(*d, xp)
        solid = e.inside([x, y, z]) | (phi <= EPS)
        n = e.normal(c, xp)
        inv = 1.0 / xp.where(solid, 1.0, phi)
        return phi, tuple(xp.where(solid, ni, di * inv) for ni, di in zip(n, d)), tuple(c)


@dataclass(frozen=True)
class CylinderShape:
    """Cylinder along z: section radii ``radii`` (x, y) and half-length ``half_length`` (scale applied)."""

    radii: tuple[float, float]
    half_length: float

    def local(self, x, y, z, xp):
        if not _isotropic(self.radii) and runs_on(x):
            from pipeline.distance import scaled_warp as distance_scaled_warp

            return distance_scaled_warp.cylinder(self.radii, self.half_length, x, y, z, xp)
        return self.local_xp(x, y, z, xp)

    def world(self, points, R, t):
        """As :meth:`SphereShape.world` (fused for an elliptic section only)."""
        if _isotropic(self.radii):
            return None
        from pipeline.distance import scaled_warp as distance_scaled_warp

        return distance_scaled_warp.cylinder_world_field(self.radii, self.half_length, points, R, t)

    def local_xp(self, x, y, z, xp):
        """The field in numpy/torch (a circular section, or where warp cannot run; the kernel's reference)."""
        return _cylinder_field(x, y, z, _Section(self.radii).closest(x, y, xp), self.half_length, xp)


@dataclass(frozen=True)
class CapsuleShape:
    """Capsule along z: sphere-swept segment [-L, L] (L = ``half_length``), ball semi-axes ``radii`` (scale applied)."""

    radii: tuple[float, float, float]
    half_length: float

    def local(self, x, y, z, xp):
        if _isotropic(self.radii):
            return self._round(x, y, z, xp)
        if runs_on(x):
            from pipeline.distance import scaled_warp as distance_scaled_warp

            return distance_scaled_warp.capsule(self.radii, self.half_length, x, y, z, xp)
        return self.local_xp(x, y, z, xp)

    def world(self, points, R, t):
        """As :meth:`SphereShape.world` (fused for a scaled capsule only)."""
        if _isotropic(self.radii):
            return None
        from pipeline.distance import scaled_warp as distance_scaled_warp

        return distance_scaled_warp.capsule_world_field(self.radii, self.half_length, points, R, t)

    def local_xp(self, x, y, z, xp):
        """The scaled capsule's field in numpy/torch (where warp cannot run; the kernel's reference)."""
        h = self.half_length
        sz, w = _sign(z), abs(z)  # fold onto z >= 0
        cap = Ellipsoid(self.radii)
        qx, qy, nx, ny, in_sec = _Section(self.radii[:2]).closest(x, y, xp)
        # outside: nearer projection onto the cylinder part and onto the cap ellipsoid E
        c1 = (xp.where(in_sec, x, qx), xp.where(in_sec, y, qy), xp.clip(w, None, h))
        d1 = _norm3(x - c1[0], y - c1[1], w - c1[2], xp)
        e = cap.closest([x, y, w - h], xp)
        c2 = (e[0], e[1], e[2] + h)
        d2 = _norm3(x - c2[0], y - c2[1], w - c2[2], xp)
        in_cap = cap.inside([x, y, w - h])
        out_c = tuple(xp.where(d2 < d1, b, a) for a, b in zip(c1, c2))
        out = xp.minimum(d1, d2)
        solid = (in_sec & (w <= h)) | in_cap | (out <= EPS)
        # inside: the cap's closest point above its centre plane, else the side (or a restricted cap point)
        top = w >= h
        side = xp.sqrt((x - qx) ** 2 + (y - qy) ** 2)
        ncap = cap.normal(e, xp)
        in_c = [xp.where(top, c2[0], qx), xp.where(top, c2[1], qy), xp.where(top, c2[2], w)]
        in_g = [xp.where(top, ncap[0], nx), xp.where(top, ncap[1], ny), xp.where(top, ncap[2], 0.0)]
        in_phi = xp.where(top, d2, side)
        if self.radii[2] < max(self.radii[:2]):
            self._restricted_cap(x, y, w, solid & ~top & (h - w < side), cap, in_phi, in_c, in_g, xp)
        inv = 1.0 / xp.where(solid, 1.0, out)
        g = [xp.where(solid, gi, (p - ci) * inv) for gi, p, ci in zip(in_g, (x, y, w), out_c)]
        c = [xp.where(solid, a, b) for a, b in zip(in_c, out_c)]
        return xp.where(solid, in_phi, out), (g[0], g[1], sz * g[2]), (c[0], c[1], sz * c[2])

    def _restricted_cap(self, x, y, w, mask, cap: Ellipsoid, phi, c, g, xp):
        """Where ``mask``: the nearest normal point of the cap's upper half, if nearer than ``phi``."""
        idx = nonzero(mask, xp)
        if len(idx) == 0:
            return
        h = self.half_length
        px, py, pz = x[idx], y[idx], w[idx] - h
        best, bq = phi[idx], [c[0][idx], c[1][idx], c[2][idx] - h]
        found = best < 0
        for q in cap.normal_points([px, py, pz], xp):
            d = _norm3(px - q[0], py - q[1], pz - q[2], xp)
            better = (q[2] >= 0) & (d < best)
            best = xp.where(better, d, best)
            bq = [xp.where(better, a, b) for a, b in zip(q, bq)]
            found = found | better
        n = cap.normal(bq, xp)
        phi[idx] = best
        for k in range(3):
            c[k][idx] = bq[k] + (h if k == 2 else 0.0)
            g[k][idx] = xp.where(found, n[k], g[k][idx])

    def _round(self, x, y, z, xp):
        r, h = self.radii[0], self.half_length
        zc = xp.clip(z, -h, h)
        vz = z - zc
        rho = _norm3(x, y, vz, xp)
        safe = xp.where(rho > 0, rho, 1.0)
        u = (xp.where(rho > 0, x / safe, 1.0), y / safe, vz / safe)
        return abs(rho - r), u, (r * u[0], r * u[1], zc + r * u[2])


@dataclass(frozen=True)
class ChairShape:
    """Union of boxes (the chair's parts); each point takes its nearest part (the first on ties).
    phi of every part first, then the full field of the nearest one only."""

    parts: tuple[tuple[BoxShape, tuple[float, float, float]], ...]

    def local(self, x, y, z, xp):
        part = nearest_box(x, y, z, [(box.half, o) for box, o in self.parts], xp)
        table = np.array([[*box.half, *o] for box, o in self.parts])
        if not isinstance(x, np.ndarray):
            table = xp.as_tensor(table, dtype=x.dtype, device=x.device)
        hx, hy, hz, ox, oy, oz = (table[part, i] for i in range(6))
        phi, g, c = box_local(x - ox, y - oy, z - oz, hx, hy, hz, xp)
        return phi, g, (c[0] + ox, c[1] + oy, c[2] + oz)

    def world(self, points, R, t):
        """As :meth:`SphereShape.world`: the fused kernel of :mod:`pipeline.distance.box_warp` (same tie rule)."""
        from pipeline.distance import box_warp as distance_box_warp

        return distance_box_warp.boxes_world_field(tuple((box.half, o) for box, o in self.parts), points, R, t)


def primitive_shape(p: Primitive):
    """The object-frame field of a (scaled) primitive."""
    s = np.asarray(p.scale)
    if p.kind == "box":
        return BoxShape(tuple(float(v) for v in np.asarray(p.size) * s))
    if p.kind == "sphere":
        return SphereShape(tuple(float(v) for v in p.size[0] * s))
    if p.kind == "cylinder":
        return CylinderShape(tuple(float(v) for v in p.size[0] * s[:2]), float(p.size[1] * s[2]))
    return CapsuleShape(tuple(float(v) for v in p.size[0] * s), float(p.size[1] * s[2]))


def chair_shape(chair: Chair) -> ChairShape:
    parts = []
    for _, prim, centre in chair.parts():
        parts.append((primitive_shape(prim), tuple(float(v) for v in centre)))
    return ChairShape(tuple(parts))
