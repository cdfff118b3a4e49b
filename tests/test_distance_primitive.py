"""Exactness of the primitive fields against brute force over the parametrised surface.

Brute force: each surface patch is sampled on a grid, the best few samples per point are refined
by repeated zooming (resolution ~1e-8 of the patch), so the brute distance is the true one to
well under 1e-6 m. Points are random inside and outside, scaled isotropically and per axis.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.distance.primitive import EPS, primitive_shape
from pipeline.geometry import Primitive

RNG = np.random.default_rng(7)


def _patches(prim: Primitive):
    """(f(u, v) -> (..., 3) unscaled, u-range, v-range) covering the surface."""
    s = prim.size
    out = []
    if prim.kind == "box":
        h = np.asarray(s)
        for ax in range(3):
            a, b = [k for k in range(3) if k != ax]
            for sign in (-1.0, 1.0):

                def f(u, v, ax=ax, a=a, b=b, sign=sign):
                    p = np.zeros(np.broadcast(u, v).shape + (3,))
                    p[..., ax], p[..., a], p[..., b] = sign * h[ax], u, v
                    return p

                out.append((f, (-h[a], h[a]), (-h[b], h[b])))
        return out

    def sph(r, zc=0.0):
        return lambda u, v: np.stack(
            np.broadcast_arrays(r * np.sin(u) * np.cos(v), r * np.sin(u) * np.sin(v), zc + r * np.cos(u)), -1
        )

    if prim.kind == "sphere":
        return [(sph(s[0]), (0, np.pi), (-np.pi, np.pi))]
    r, hl = s
    side = lambda u, v: np.stack(np.broadcast_arrays(r * np.cos(u), r * np.sin(u), v), -1)  # noqa: E731
    out.append((side, (-np.pi, np.pi), (-hl, hl)))
    if prim.kind == "cylinder":
        for zc in (-hl, hl):
            disk = lambda u, v, zc=zc: np.stack(np.broadcast_arrays(u * np.cos(v), u * np.sin(v), zc + 0 * u), -1)  # noqa: E731
            out.append((disk, (0, r), (-np.pi, np.pi)))
        return out
    out.append((sph(r, hl), (0, np.pi / 2), (-np.pi, np.pi)))
    out.append((sph(r, -hl), (np.pi / 2, np.pi), (-np.pi, np.pi)))
    return out


def brute_distance(prim: Primitive, p: np.ndarray) -> np.ndarray:
    scale = np.asarray(prim.scale)
    best = np.full(len(p), np.inf)
    for f, (u0, u1), (v0, v1) in _patches(prim):
        g = 120
        u, v = np.meshgrid(np.linspace(u0, u1, g), np.linspace(v0, v1, g), indexing="ij")
        d = np.linalg.norm(f(u, v)[None] * scale - p[:, None, None], axis=-1).reshape(len(p), -1)
        for k in np.argsort(d, axis=1)[:, :3].T:
            du, dv = (u1 - u0) / (g - 1), (v1 - v0) / (g - 1)
            cu, cv = u.ravel()[k], v.ravel()[k]
            for _ in range(7):
                lu = np.clip(cu[:, None] + np.linspace(-2, 2, 21) * du, u0, u1)
                lv = np.clip(cv[:, None] + np.linspace(-2, 2, 21) * dv, v0, v1)
                pts = f(lu[:, :, None], lv[:, None, :]) * scale
                dd = np.linalg.norm(pts - p[:, None, None], axis=-1).reshape(len(p), -1)
                j = np.argmin(dd, axis=1)
                cu, cv = lu[np.arange(len(p)), j // 21], lv[np.arange(len(p)), j % 21]
                du, dv = du / 5, dv / 5
            best = np.minimum(best, dd.min(axis=1))
    return best


def inside_solid(prim: Primitive, p: np.ndarray) -> np.ndarray:
    q = p / np.asarray(prim.scale)
    s = prim.size
    if prim.kind == "box":
        return (np.abs(q) < np.asarray(s)).all(axis=1)
    if prim.kind == "sphere":
        return np.linalg.norm(q, axis=1) < s[0]
    rho = np.linalg.norm(q[:, :2], axis=1)
    if prim.kind == "cylinder":
        return (rho < s[0]) & (np.abs(q[:, 2]) < s[1])
    zc = np.clip(q[:, 2], -s[1], s[1])
    return np.hypot(rho, q[:, 2] - zc) < s[0]


PRIMS = [
    Primitive("box", (0.3, 0.2, 0.1)),
    Primitive("box", (0.3, 0.2, 0.1), (1.0, 2.0, 0.5)),
    Primitive("sphere", (0.2,)),
    Primitive("sphere", (0.2,), (1.0, 1.5, 0.5)),
    Primitive("cylinder", (0.1, 0.3)),
    Primitive("cylinder", (0.1, 0.3), (1.6, 1.6, 0.4)),
    Primitive("cylinder", (0.1, 0.3), (2.0, 1.0, 0.7)),
    Primitive("capsule", (0.1, 0.2)),
    Primitive("capsule", (0.1, 0.2), (1.0, 1.0, 2.0)),
    Primitive("capsule", (0.1, 0.2), (2.0, 1.5, 0.6)),
    Primitive("capsule", (0.1, 0.05), (2.0, 2.0, 0.5)),
]


def _points(prim: Primitive, n: int) -> np.ndarray:
    ext = np.abs(
        np.concatenate(
            [f(*np.meshgrid(np.linspace(*ur, 9), np.linspace(*vr, 9))).reshape(-1, 3) for f, ur, vr in _patches(prim)]
        )
    )
    rng = np.random.default_rng(7)  # per call: the points do not depend on which tests ran before (xdist order)
    p = rng.uniform(-1.4, 1.4, (n, 3)) * ext.max(axis=0) * np.asarray(prim.scale)
    p[:8, :2] = 0.0  # on the axis
    p[8:16, 2] = 0.0  # on the mid-plane
    return p


@pytest.mark.parametrize("prim", PRIMS, ids=lambda p: f"{p.kind}{p.scale}")
def test_phi_equals_brute_force_distance_inside_and_outside(prim):
    p = _points(prim, 120)
    phi, g, c = primitive_shape(prim).local(*p.T, np)
    g, c = np.stack(g, 1), np.stack(c, 1)
    inside = inside_solid(prim, p)
    assert 0.1 < inside.mean() < 0.8  # a sphere fills 19% of the sampled box: both sides are well covered
    np.testing.assert_allclose(phi, brute_distance(prim, p), rtol=0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(p - c, axis=1), phi, rtol=0, atol=1e-12)
    assert primitive_shape(prim).local(*c.T, np)[0].max() < 1e-9  # closest points lie on the surface
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-12)
    # outside: grad = (p - c)/phi; inside: the outward normal at c, i.e. pointing from p to c
    np.testing.assert_allclose(g[~inside] * phi[~inside, None], (p - c)[~inside], atol=1e-12)
    np.testing.assert_allclose(g[inside] * phi[inside, None], (c - p)[inside], atol=1e-9)


@pytest.mark.parametrize("prim", PRIMS, ids=lambda p: f"{p.kind}{p.scale}")
def test_grad_on_the_surface_is_the_outward_normal(prim):
    shape = primitive_shape(prim)
    s = []
    for f, (u0, u1), (v0, v1) in _patches(prim):  # points inside each patch, off its edges
        u, v = RNG.uniform(0.05, 0.95, (2, 40))
        s.append(f(u0 + u * (u1 - u0), v0 + v * (v1 - v0)) * np.asarray(prim.scale))
    s = np.concatenate(s)
    phi, g, c = shape.local(*s.T, np)
    g = np.stack(g, 1)
    assert phi.max() <= EPS
    d = 1e-5
    out, inn = s + d * g, s - d * g
    assert not inside_solid(prim, out).any() and inside_solid(prim, inn).all()
    np.testing.assert_allclose(shape.local(*out.T, np)[0], d, rtol=1e-3)


def test_box_inside_takes_the_nearest_face():
    phi, g, c = primitive_shape(Primitive("box", (0.3, 0.2, 0.1))).local(
        np.array([0.27]), np.array([0.0]), np.array([0.0]), np
    )
    assert phi[0] == pytest.approx(0.03) and [a[0] for a in g] == [1.0, 0.0, 0.0] and c[0][0] == pytest.approx(0.3)
