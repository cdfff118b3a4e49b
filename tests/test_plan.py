"""ZMP preview control: the planned ZMP follows its reference; clipping into the support polygon."""

import numpy as np

from physicalize.plan import GRAVITY, HandLoads, clip_to_polygon, hand_cop_shift, preview_gains

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


def test_hand_cop_shift_balances_the_moments_about_the_centre_of_pressure():
    """With the CoP shifted by ``hand_cop_shift``, gravity at the CoM and the hands' reactions have no
    horizontal moment about the CoP on the floor (static balance), for pushes, pulls and lifted loads."""
    rng = np.random.default_rng(0)
    T, mass = 50, 35.0
    com = np.column_stack([rng.uniform(-0.2, 0.2, (T, 2)), rng.uniform(0.5, 0.7, T)])
    point = com[:, None, :] + rng.uniform(-0.4, 0.4, (T, 2, 3))
    force = rng.uniform(-60, 60, (T, 2, 3))  # what the hands apply to the object; the robot gets -force
    e = hand_cop_shift(com, HandLoads(point, force, mass))
    p = np.column_stack([com[:, :2] + e, np.zeros(T)])
    moment = np.cross(com - p, [0.0, 0.0, -mass * GRAVITY]) + np.cross(point - p[:, None], -force).sum(axis=1)
    assert np.abs(moment[:, :2]).max() < 1e-9


def test_a_push_moves_the_centre_of_pressure_behind_the_com():
    """Pushing 50 N forward at 1 m height: the CoP is 50 / (m g) behind the CoM (the human leans in)."""
    com = np.array([[0.0, 0.0, 0.6]])
    loads = HandLoads(np.array([[[0.3, 0.2, 1.0], [0.3, -0.2, 1.0]]]), np.array([[[25.0, 0, 0], [25.0, 0, 0]]]), 35.0)
    e = hand_cop_shift(com, loads)
    assert np.allclose(e, [[-50.0 / (35.0 * GRAVITY), 0.0]])
