"""ZMP preview control: the planned ZMP follows its reference; clipping into the support polygon."""

import numpy as np

from physicalize.plan import GRAVITY, clip_to_polygon, preview_gains

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def test_point_inside_the_polygon_is_kept():
    assert np.allclose(clip_to_polygon(np.array([0.5, 0.4]), SQUARE, margin=0.0), [0.5, 0.4])


def test_point_outside_goes_to_the_shrunk_boundary():
    p = clip_to_polygon(np.array([2.0, 0.5]), SQUARE, margin=0.1)
    assert p[0] < 1.0 and p[0] > 0.85 and abs(p[1] - 0.5) < 1e-9


def test_preview_control_follows_a_zmp_step():
    """The cart-table model under the preview law moves its ZMP from 0 to 0.1 m (a weight shift
    onto the other foot) and ends at rest over the new ZMP."""
    dt, zc, n = 0.02, 0.7, 80
    gi, gx, gd = preview_gains(dt, zc, n)
    T = 200
    pref = np.where(np.arange(T + n) >= 100, 0.1, 0.0)
    A = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    B = np.array([dt**3 / 6, dt * dt / 2, dt])
    x, err, zmp, com = np.zeros(3), 0.0, [], []
    for k in range(T):
        p = x[0] - zc / GRAVITY * x[2]
        com.append(x[0])
        zmp.append(p)
        err += p - pref[k]
        x = A @ x + B * (-gi * err - gx @ x - gd @ pref[k + 1 : k + 1 + n])
    zmp = np.array(zmp)
    assert abs(x[0] - 0.1) < 2e-3 and abs(x[1]) < 1e-2
    assert np.abs(zmp - pref[:T]).max() < 0.05  # the ZMP leaves early (preview) but never overshoots far
    assert com[95] > 0.01  # the CoM sets off before the ZMP steps (preview)
