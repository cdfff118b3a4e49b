"""Closest points on ellipses and ellipsoids against dense sampling of the curve."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.distance.ellipsoid import Ellipsoid


def test_ellipse_closest_point_matches_dense_sampling():
    a = (0.5, 0.1)
    th = np.linspace(-np.pi, np.pi, 400_001)  # 8e-6 m apart: the sampled minimum is off by < 1e-9 m
    curve = np.stack([a[0] * np.cos(th), a[1] * np.sin(th)], 1)
    rng = np.random.default_rng(3)
    p = rng.uniform(-0.7, 0.7, (60, 2)) * [1, 0.4]
    p[:5, 1] = 0.0  # on the long axis: inside, the evolute's segment (two closest points)
    p[5] = 0.0
    q = np.stack(Ellipsoid(a).closest(list(p.T), np), 1)
    brute = np.array([np.linalg.norm(curve - x, axis=1).min() for x in p])
    np.testing.assert_allclose(np.linalg.norm(p - q, axis=1), brute, atol=1e-6)
    np.testing.assert_allclose(((q / a) ** 2).sum(1), 1.0, atol=1e-12)


def test_normal_points_contain_the_closest_point_and_are_normal():
    e = Ellipsoid((0.3, 0.2, 0.1))
    p = np.random.default_rng(4).normal(size=(500, 3)) * 0.2
    q = np.stack(e.closest(list(p.T), np), 1)
    cands = [np.stack(c, 1) for c in e.normal_points(list(p.T), np)]
    dist = np.stack([np.linalg.norm(p - c, axis=1) for c in cands])
    np.testing.assert_allclose(np.nanmin(dist, axis=0), np.linalg.norm(p - q, axis=1), atol=1e-12)
    normal = 0
    for c in cands:  # every candidate that exists lies on the surface; the roots are normal points
        ok = np.isfinite(c).all(1)
        np.testing.assert_allclose(((c[ok] / e.axes) ** 2).sum(1), 1.0, atol=1e-12)
        n = np.stack(e.normal(list(c[ok].T), np), 1)
        r = p[ok] - c[ok]
        normal += (np.abs(r - (r * n).sum(1, keepdims=True) * n).max(1) < 1e-7).sum()
    assert normal > len(p)  # the closest point of each, and more normal points for some


@pytest.mark.parametrize("axes", [(1.0,), (1.0, 0.0), (1.0, np.nan, 2.0)])
def test_bad_semi_axes_are_rejected(axes):
    with pytest.raises(ValueError, match="semi-axes"):
        Ellipsoid(axes)
