"""Closest points on an axis-aligned ellipse or ellipsoid: the per-axis scaled sphere, cylinder, capsule.

A sphere, cylinder or capsule scaled per axis has elliptic sections and ellipsoidal caps. A
point q of the surface sum_i (q_i / a_i)^2 = 1 where p - q is normal to the surface satisfies
the Lagrange condition q_i = a_i^2 p_i / (a_i^2 + t) for a t with

    g(t) = sum_i (a_i p_i / (a_i^2 + t))^2 = 1

(Eberly, "Distance from a point to an ellipse, an ellipsoid, or a hyperellipsoid", 2013).
Working with |p_i| (signs restored at the end):

* the closest point is the one root with t > -a_min^2 (g falls from +inf to 0 there), or, where
  p lies on the plane of the shortest axis (p_min = 0) and that root does not exist, the point
  t = -a_min^2: q_i = a_i^2 p_i / (a_i^2 - a_min^2) for the other axes, q_min from the surface;
* the other normal points (candidates for a distance restricted to part of the surface, as for a
  capsule's cap) are the roots between two poles t = -a_i^2, where g is convex: none or two,
  either side of its minimum, and the pole points of the same formula.

Roots are found by Newton steps on F = g^(-1/2) - 1, which is nearly linear in t, kept inside a
shrinking bracket (bisection when a step leaves it); every candidate is then scaled onto the
surface, so it is a surface point to rounding whatever happened. Equal semi-axes are merged
into one radial coordinate first (a spheroid is an ellipse problem, a sphere needs no solve).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.xp import nonzero

_MAX_STEPS = 80
_REL_TOL = 1e-15


def _newton(f, lo, hi, increasing: bool, xp, args):
    """Root in (lo, hi) of a monotone f; ``f(s, args) -> (value, derivative)``, ``args`` per-point
    columns. Points stop once converged; the stragglers continue alone. Returns s."""
    s = 0.5 * (lo + hi)
    act = nonzero(s == s, xp)
    s_a, lo_a, hi_a, args_a = s, lo, hi, list(args)
    for _ in range(_MAX_STEPS):
        v, dv = f(s_a, args_a)
        below = (v < 0) if increasing else (v > 0)  # the root lies above s
        lo_a = xp.where(below, s_a, lo_a)
        hi_a = xp.where(below, hi_a, s_a)
        step = s_a - v / dv
        step = xp.where((step > lo_a) & (step < hi_a), step, 0.5 * (lo_a + hi_a))
        done = (abs(step - s_a) <= _REL_TOL * abs(s_a)) | (hi_a - lo_a <= _REL_TOL * abs(hi_a))
        s[act] = step
        if bool(done.all()):
            break
        keep = nonzero(~done, xp)
        act, s_a, lo_a, hi_a = act[keep], step[keep], lo_a[keep], hi_a[keep]
        args_a = [a[keep] for a in args_a]
    return s


def _sign(c):
    """+1 or -1, with +1 at zero."""
    return 1.0 - 2.0 * (c < 0)


@dataclass(frozen=True)
class Ellipsoid:
    """Axis-aligned ellipse (two semi-axes) or ellipsoid (three) centred at the origin."""

    axes: tuple[float, ...]
    _groups: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        a = tuple(float(v) for v in self.axes)
        if len(a) not in (2, 3) or not all(np.isfinite(a)) or min(a) <= 0:
            raise ValueError(f"ellipsoid semi-axes must be 2 or 3 positive numbers, got {self.axes!r}")
        object.__setattr__(self, "axes", a)
        groups: list[tuple[float, list[int]]] = []
        for i, ai in enumerate(a):
            for b, members in groups:
                if abs(b - ai) <= 1e-12 * max(b, ai):
                    members.append(i)
                    break
            else:
                groups.append((ai, [i]))
        object.__setattr__(self, "_groups", tuple((b, tuple(m)) for b, m in groups))

    # -- reduced (merged-axes, first-orthant) coordinates ---------------------------------------
    def _reduce(self, p, xp):
        """(y_k >= 0 per group, unit vectors per axis) with p_i = unit_i * y_group(i)."""
        ys, units = [], [None] * len(self.axes)
        for _, members in self._groups:
            if len(members) == 1:
                c = p[members[0]]
                ys.append(abs(c))
                units[members[0]] = _sign(c)
                continue
            r = xp.sqrt(sum(p[i] * p[i] for i in members))
            safe = xp.where(r > 0, r, 1.0)
            for j, i in enumerate(members):
                units[i] = xp.where(r > 0, p[i] / safe, 1.0 if j == 0 else 0.0)
            ys.append(r)
        return ys, units

    def _restore(self, q, units):
        out = [None] * len(self.axes)
        for k, (_, members) in enumerate(self._groups):
            for i in members:
                out[i] = units[i] * q[k]
        return out

    def _onto_surface(self, q, xp):
        b = [g[0] for g in self._groups]
        norm = xp.sqrt(sum((qk / bk) ** 2 for qk, bk in zip(q, b)))
        return [qk / norm for qk in q]

    # -- candidates in reduced coordinates -------------------------------------------------------
    def _root_above(self, y, xp):
        """The root t > -b_min^2 (the closest point), solved for s = t + b_min^2 > 0."""
        b = [g[0] for g in self._groups]
        m = int(np.argmin(b))
        shift = [bk * bk - b[m] * b[m] for bk in b]

        def f(s, y):
            d = [s + sh for sh in shift]
            term2 = [(bk * yk / dk) ** 2 for bk, yk, dk in zip(b, y, d)]
            g = sum(term2)
            inv = 1.0 / xp.sqrt(g)
            return inv - 1.0, inv**3 * sum(t2 / dk for t2, dk in zip(term2, d))

        ny = xp.sqrt(sum(yk * yk for yk in y))
        s = _newton(f, 0.0 * ny, max(b) * ny * (1 + 1e-12) + 1e-300, True, xp, y)
        return [bk * bk * yk / (s + sh) for bk, yk, sh in zip(b, y, shift)]

    def _pole_point(self, y, k: int, xp):
        """t = -b_k^2: q_i = b_i^2 y_i / (b_i^2 - b_k^2) (i != k), q_k >= 0 from the surface; NaN off it."""
        b = [g[0] for g in self._groups]
        q = [b[i] ** 2 * y[i] / (b[i] ** 2 - b[k] ** 2) if i != k else None for i in range(len(b))]
        rest = 1.0 - sum((q[i] / b[i]) ** 2 for i in range(len(b)) if i != k)
        q[k] = b[k] * xp.sqrt(xp.where(rest >= 0, rest, float("nan")))
        return q

    def _roots_between(self, y, lo_k: int, hi_k: int, xp):
        """The (up to) two roots between the poles -b_lo^2 < -b_hi^2 (b_lo > b_hi)."""
        b = [g[0] for g in self._groups]
        length = b[lo_k] ** 2 - b[hi_k] ** 2
        shift = [bk * bk - b[lo_k] ** 2 for bk in b]  # d_k = s + shift_k, s = t + b_lo^2 in (0, length)

        def parts(s, y):
            d = [s + sh for sh in shift]
            return d, [(bk * yk / dk) ** 2 for bk, yk, dk in zip(b, y, d)]

        def slope(s, y):  # -g'/2, decreasing in s
            d, t2 = parts(s, y)
            return sum(t / dk for t, dk in zip(t2, d)), -3.0 * sum(t / (dk * dk) for t, dk in zip(t2, d))

        def f(s, y):
            d, t2 = parts(s, y)
            inv = 1.0 / xp.sqrt(sum(t2))
            return inv - 1.0, inv**3 * sum(t / dk for t, dk in zip(t2, d))

        zero = 0.0 * y[0]
        s_min = _newton(slope, zero, zero + length, False, xp, y)
        exists = f(s_min, y)[0] >= 0  # g <= 1 at its minimum
        roots = [_newton(f, zero, s_min, True, xp, y), _newton(f, s_min, zero + length, False, xp, y)]
        return [
            [xp.where(exists, bk * bk * yk / (s + sh), float("nan")) for bk, yk, sh in zip(b, y, shift)] for s in roots
        ]

    # -- public ------------------------------------------------------------------------------------
    def inside(self, p) -> object:
        """True where sum (p_i / a_i)^2 < 1."""
        return sum((pi / ai) ** 2 for pi, ai in zip(p, self.axes)) < 1.0

    def normal(self, q, xp) -> list:
        """Outward unit normal at surface points q: normalise (q_i / a_i^2)."""
        n = [qi / (ai * ai) for qi, ai in zip(q, self.axes)]
        norm = xp.sqrt(sum(c * c for c in n))
        return [c / norm for c in n]

    def closest(self, p, xp) -> list:
        """Closest surface point to p (a list of coordinate columns), from inside or outside."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            y, units = self._reduce(p, xp)
            if len(self._groups) == 1:
                return self._restore([y[0] * 0.0 + self._groups[0][0]], units)
            b = [g[0] for g in self._groups]
            root = self._onto_surface(self._root_above(y, xp), xp)
            pole = self._onto_surface(self._pole_point(y, int(np.argmin(b)), xp), xp)
            d_root = sum((yk - qk) ** 2 for yk, qk in zip(y, root))
            d_pole = sum((yk - qk) ** 2 for yk, qk in zip(y, pole))
            use_pole = ~(d_root <= d_pole) & xp.isfinite(d_pole)
            q = [xp.where(use_pole, qp, qr) for qp, qr in zip(pole, root)]
            return self._restore(q, units)

    def normal_points(self, p, xp) -> list[list]:
        """Surface points q that include every one where p - q is normal to the surface: the
        candidates for the closest point of a restricted part of the surface. Pole points are
        included whenever they are on the surface (they are normal points only for p on an axis
        plane, and keep the result exact near one); a candidate that does not exist is NaN."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            y, units = self._reduce(p, xp)
            b = [g[0] for g in self._groups]
            if len(b) == 1:
                return [self._restore([y[0] * 0.0 + s * b[0]], units) for s in (1.0, -1.0)]
            cands = [self._root_above(y, xp)]
            order = sorted(range(len(b)), key=lambda k: -b[k])  # poles -b^2 ascending
            for lo_k, hi_k in zip(order[:-1], order[1:]):
                cands += self._roots_between(y, lo_k, hi_k, xp)
            for k in range(len(b)):
                q = self._pole_point(y, k, xp)
                cands += [q, [-c if i == k else c for i, c in enumerate(q)]]
            return [self._restore(self._onto_surface(q, xp), units) for q in cands]
