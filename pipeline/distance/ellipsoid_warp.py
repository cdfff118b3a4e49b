"""The ellipse/ellipsoid closest-point solve of :mod:`pipeline.distance.ellipsoid` as warp functions, in float64.

Same math, point by point: with the semi-axes merged into groups of equal length (one radial
coordinate y_k >= 0 per group, unit factors u_i restoring the axes, p_i = u_i y_group(i)), the
closest point is the root s = t + b_min^2 > 0 of

    F(s) = g^(-1/2) - 1,    g = sum_k (b_k y_k / d_k)^2,    d_k = s + b_k^2 - b_min^2,

q_k = b_k^2 y_k / d_k; where p is on the plane of the shortest axis (y_min = 0) and g(0) <= 1
there is no root and the closest point is the pole point t = -b_min^2. The other normal points
(a restricted distance, as for a capsule's cap) are the two roots of F between consecutive poles,
either side of the minimum of g (the root of -g'/2 = sum_k (b_k y_k)^2 / d_k^3, which decreases),
and the pole points with either sign of the pole's coordinate. Every candidate is scaled onto
the surface; one that does not exist is NaN.

Roots: Newton steps inside a shrinking bracket. F is concave and increasing (a power mean of
the d_k with exponent -2), so from the left Newton climbs monotonically to the root. A step that
leaves the bracket from the right takes the pole step instead where it lands inside, else bisects:
g >= (b_min y_min / s)^2 + R(hi) with R the other terms, which fall with s, so

    s >= b_min y_min / sqrt(1 - R(hi))

is a lower bound on the root (points near the shortest axis' plane, where F bends sharply near
s = 0). Iteration stops at a relative 1e-15 in s or in the bracket, when a step returns to a
bracket end (the rounding floor of F), when the next step's correction F''/(2F') step^2 is below
1e-17 s, or after 80 steps. (The numpy reference bisects where a step lands on a bracket end, so
its foot points can be off the normal line by ~1e-8 where the kernel's are on it to rounding.)

Layout (:class:`Spec`): three slots, the groups in decreasing order ending in slot 2 (the shortest
axis); unused leading slots have y = 0 and b = b_max, so they add nothing and never divide by zero.
"""

from __future__ import annotations

import warp as wp

from pipeline.distance.ellipsoid import Ellipsoid

MAX_STEPS = 80


@wp.struct
class Spec:
    """``ng`` groups in slots 3-ng..2 with semi-axes ``b`` (squares ``b2``, reciprocals ``inv_b``);
    ``m[k, i]`` = 1 where axis i is in slot k; ``first[i]`` = 1 for a group's first axis; ``axes``
    the semi-axes per axis (reciprocals ``inv_axes``)."""

    ng: int
    axes: wp.vec3d
    inv_axes: wp.vec3d
    b: wp.vec3d
    inv_b: wp.vec3d
    b2: wp.vec3d
    m: wp.mat33d
    first: wp.vec3d


def spec(e: Ellipsoid) -> Spec:
    """The kernel description of ``e`` (an ellipse lies in the x-y plane: axis 2 in no group)."""
    groups = sorted(e._groups, key=lambda g: -g[0])
    pad = 3 - len(groups)
    b = [groups[0][0]] * pad + [g[0] for g in groups]
    m, first = [[0.0] * 3 for _ in range(3)], [0.0] * 3
    for k, (_, members) in enumerate(groups):
        for j, i in enumerate(members):
            m[pad + k][i], first[i] = 1.0, float(j == 0)
    s = Spec()
    s.ng = len(groups)
    axes = [*e.axes, *[1.0] * (3 - len(e.axes))]
    s.axes, s.inv_axes = wp.vec3d(*axes), wp.vec3d(*[1.0 / v for v in axes])
    s.b, s.inv_b, s.b2 = wp.vec3d(*b), wp.vec3d(*[1.0 / v for v in b]), wp.vec3d(*[v * v for v in b])
    s.m, s.first = wp.mat33d(*[v for row in m for v in row]), wp.vec3d(*first)
    return s


@wp.func
def _nan() -> wp.float64:
    z = wp.float64(0.0)
    return z / z


@wp.func
def _nan3() -> wp.vec3d:
    return wp.vec3d(_nan(), _nan(), _nan())


@wp.func
def sign(c: wp.float64) -> wp.float64:
    """+1 or -1, with +1 at zero."""
    if c < wp.float64(0.0):
        return wp.float64(-1.0)
    return wp.float64(1.0)


@wp.func
def reduce(e: Spec, p: wp.vec3d) -> wp.vec3d:
    """y_k = sqrt(sum of p_i^2 over the slot's axes) (|p_i| for a one-axis group)."""
    y = e.m * wp.cw_mul(p, p)
    return wp.vec3d(wp.sqrt(y[0]), wp.sqrt(y[1]), wp.sqrt(y[2]))


@wp.func
def units(e: Spec, p: wp.vec3d, y: wp.vec3d) -> wp.vec3d:
    """u_i = p_i / y_group(i) (the sign for a one-axis group); where y = 0, 1 on the group's first axis."""
    r = wp.transpose(e.m) * y
    u = wp.vec3d()
    for i in range(3):
        if r[i] > wp.float64(0.0):
            u[i] = p[i] / r[i]
        else:
            u[i] = e.first[i]
    return u


@wp.func
def restore(e: Spec, q: wp.vec3d, u: wp.vec3d) -> wp.vec3d:
    """p_i = u_i q_group(i)."""
    return wp.cw_mul(u, wp.transpose(e.m) * q)


@wp.func
def onto_surface(e: Spec, q: wp.vec3d) -> wp.vec3d:
    """q / sqrt(sum (q_k / b_k)^2): the candidate scaled onto the surface."""
    r = wp.cw_mul(q, e.inv_b)
    return q / wp.sqrt(wp.dot(r, r))


@wp.func
def _eval(slope: int, s: wp.float64, y: wp.vec3d, e: Spec, base2: wp.float64) -> wp.vec4d:
    """At d_k = s + b_k^2 - base2: (1 - g (F's sign), the Newton step -F/F' = g (sqrt(g) - 1) / a,
    g less the slot-2 term, F''/(2F') = 3 (a^2 - g c) / (2 g a)) with a = -g'/2 = sum t_k^2 / d_k,
    c = sum t_k^2 / d_k^2; or with ``slope`` (a, its Newton step a / (3c), 0, 0)."""
    g = wp.float64(0.0)
    a = wp.float64(0.0)
    c = wp.float64(0.0)
    t2 = wp.float64(0.0)
    for k in range(3):
        r = wp.float64(1.0) / (s + (e.b2[k] - base2))
        t = e.b[k] * y[k] * r
        t2 = t * t
        g = g + t2
        a = a + t2 * r
        c = c + t2 * r * r
    if slope == 1:
        return wp.vec4d(a, a / (wp.float64(3.0) * c), wp.float64(0.0), wp.float64(0.0))
    ia = wp.float64(1.0) / a
    curv = wp.float64(1.5) * (a * a - g * c) * ia / g
    return wp.vec4d(wp.float64(1.0) - g, g * (wp.sqrt(g) - wp.float64(1.0)) * ia, g - t2, curv)


@wp.func
def _newton(
    slope: int, increasing: int, pole: int, y: wp.vec3d, e: Spec, base2: wp.float64, lo0: wp.float64, hi0: wp.float64
) -> wp.float64:
    """Root in (lo0, hi0) of the monotone F (or -g'/2): Newton steps in the bracket, else the pole step (``pole``) or
    bisection."""
    lo = lo0
    hi = hi0
    s = wp.float64(0.5) * (lo + hi)
    tol = wp.float64(1e-15)
    for _ in range(MAX_STEPS):
        v = _eval(slope, s, y, e, base2)
        below = False  # the root lies above s
        if increasing == 1:
            below = v[0] < wp.float64(0.0)
        else:
            below = v[0] > wp.float64(0.0)
        if below:
            lo = s
        else:
            hi = s
        step = s + v[1]
        newton = step >= lo and step <= hi
        if not newton:
            step = wp.float64(0.5) * (lo + hi)
            if pole == 1 and not below and v[2] < wp.float64(1.0):
                sp = e.b[2] * y[2] / wp.sqrt(wp.float64(1.0) - v[2])
                if sp > lo and sp < hi:
                    step = sp
        done = wp.abs(step - s) <= tol * wp.abs(s) or hi - lo <= tol * wp.abs(hi) or step == lo or step == hi
        if newton and slope == 0 and wp.abs(v[3]) * v[1] * v[1] <= wp.float64(1e-17) * wp.abs(step):
            done = True  # the next step's correction, F''/(2F') step^2, is below rounding
        s = step
        if done:
            break
    return s


@wp.func
def _point(e: Spec, y: wp.vec3d, s: wp.float64, base2: wp.float64) -> wp.vec3d:
    """q_k = b_k^2 y_k / (s + b_k^2 - base2)."""
    q = wp.vec3d()
    for k in range(3):
        q[k] = e.b2[k] * y[k] / (s + (e.b2[k] - base2))
    return q


@wp.func
def root_above(e: Spec, y: wp.vec3d) -> wp.vec3d:
    """The root t > -b_min^2; NaN where y_min = 0 and g(t = -b_min^2) <= 1 (no root)."""
    bm2 = e.b2[2]
    zero = wp.float64(0.0)
    if y[2] == zero:
        g0 = zero
        for k in range(2):
            t = e.b[k] * y[k] / (e.b2[k] - bm2)
            g0 = g0 + t * t
        if g0 <= wp.float64(1.0):
            return _nan3()
    hi = e.b[0] * wp.length(y) * wp.float64(1.000000000001) + wp.float64(1e-300)
    return _point(e, y, _newton(0, 1, 1, y, e, bm2, zero, hi), bm2)


@wp.func
def pole_point(e: Spec, y: wp.vec3d, k: int) -> wp.vec3d:
    """t = -b_k^2: q_i = b_i^2 y_i / (b_i^2 - b_k^2) (i != k), q_k >= 0 from the surface; NaN off it."""
    q = wp.vec3d()
    rest = wp.float64(1.0)
    for i in range(3 - e.ng, 3):
        if i != k:
            q[i] = e.b2[i] * y[i] / (e.b2[i] - e.b2[k])
            r = q[i] / e.b[i]
            rest = rest - r * r
    if rest >= wp.float64(0.0):
        q[k] = e.b[k] * wp.sqrt(rest)
    else:
        q[k] = _nan()
    return q


@wp.func
def root_between(e: Spec, y: wp.vec3d, lo_k: int, right: int) -> wp.vec3d:
    """The left (``right`` = 0) or right root between the poles -b_lo^2 < -b_(lo+1)^2; NaN if none."""
    base2 = e.b2[lo_k]
    length = base2 - e.b2[lo_k + 1]
    zero = wp.float64(0.0)
    s_min = _newton(1, 0, 0, y, e, base2, zero, length)
    if not (_eval(0, s_min, y, e, base2)[0] >= zero):  # g > 1 at its minimum: no root
        return _nan3()
    s = zero
    if right == 0:
        s = _newton(0, 1, 0, y, e, base2, zero, s_min)
    else:
        s = _newton(0, 0, 0, y, e, base2, s_min, length)
    return _point(e, y, s, base2)


@wp.func
def closest(e: Spec, p: wp.vec3d) -> wp.vec3d:
    """Closest surface point to p, from inside or outside."""
    y = reduce(e, p)
    u = units(e, p, y)
    if e.ng == 1:
        return restore(e, wp.vec3d(wp.float64(0.0), wp.float64(0.0), e.b[2]), u)
    q = root_above(e, y)
    if not wp.isfinite(q[0] + q[1] + q[2]):
        q = pole_point(e, y, 2)
    return restore(e, onto_surface(e, q), u)


@wp.func
def normal_point_count(e: Spec) -> int:
    """Candidates of :func:`normal_point`: the root above, two per pair of poles, two per pole (a sphere: 2)."""
    if e.ng == 1:
        return 2
    return 1 + 2 * (e.ng - 1) + 2 * e.ng


@wp.func
def normal_point(e: Spec, y: wp.vec3d, u: wp.vec3d, j: int) -> wp.vec3d:
    """Candidate j of the surface points that include every normal point of p (reduced y, units u)."""
    q = wp.vec3d()
    if e.ng == 1:
        q[2] = e.b[2]
        if j == 1:
            q[2] = -e.b[2]
        return restore(e, q, u)
    f = 3 - e.ng
    pairs = 2 * (e.ng - 1)
    if j == 0:
        q = root_above(e, y)
    elif j <= pairs:
        q = root_between(e, y, f + (j - 1) // 2, (j - 1) % 2)
    else:
        k = f + (j - 1 - pairs) // 2
        q = pole_point(e, y, k)
        if (j - 1 - pairs) % 2 == 1:
            q[k] = -q[k]
    return restore(e, onto_surface(e, q), u)


@wp.func
def inside(e: Spec, p: wp.vec3d) -> bool:
    """sum (p_i / a_i)^2 < 1."""
    r = wp.cw_mul(p, e.inv_axes)
    return wp.dot(r, r) < wp.float64(1.0)


@wp.func
def normal(e: Spec, q: wp.vec3d) -> wp.vec3d:
    """Outward unit normal at a surface point q: normalise (q_i / a_i^2)."""
    return wp.normalize(wp.cw_mul(wp.cw_mul(q, e.inv_axes), e.inv_axes))
