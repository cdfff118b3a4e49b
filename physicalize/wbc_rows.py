"""The whole-body QP's soft inequality rows (called by :meth:`physicalize.wbc.WholeBodyController.solve`):
joint-range barriers, swing-foot touchdown speed caps and leg-object clearance, ``G qdd <= h``, each kept with a slack
``s >= 0`` of weight ``w_limit_slack`` so that the QP stays feasible where a row cannot hold
(``G qdd - s <= h``). ``ctrl`` is the :class:`~physicalize.wbc.WholeBodyController`.

Measured and not kept: range rows only off the stance legs (violations up to 0.197 of frames
remained); zero force on stance sole corners more than 1 cm above the floor (walk penetration
0.030 -> 0.021 m, but the frames before a fall over the 7 benchmark clips fell 1440 -> 1228)."""

from __future__ import annotations

import mujoco
import numpy as np

from pipeline.robot import JOINTS_QPOS, JOINTS_QVEL, NV_ROBOT

TOUCHDOWN_RATE = 25.0  # a [1/s] of the swing-foot touchdown rows (soft_rows)


def soft_rows(ctrl, d, target, stance: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Inequality rows ``G qdd <= h`` (``G`` (k, 35)) that the QP keeps with a slack:

    * joint ranges: ``-qdd_j <= -b_lo,j`` and ``qdd_j <= b_hi,j`` (:func:`limit_bounds`), for the
      rows whose bound is within ``limit_active`` (the others cannot bind);
    * swing-foot touchdown: each sole corner of a swing foot lower than ``touchdown_zone``, height
      ``z`` and vertical speed ``zd`` (``zdd = J_z qdd + Jdot_z qd``), descends at most at
      ``v = touchdown_speed``: ``zdd >= -a (zd + v)`` (``a`` = :data:`TOUCHDOWN_RATE`), so a foot is not
      driven into the floor (the floor's soft contact let a 2 m/s strike sink the sole 3.5 cm). A
      barrier towards a depth below the floor instead (like the joint ranges') measured worse: it
      delayed landings (Push fell at 108-143 frames with it, 207-277 without);
    * legs off objects (:func:`clearance_rows`): no contact between a leg link and an object is planned,
      and one measured in the simulation is a force the QP never chose (PickUp's knee came down on the
      box's top edge, 110 N up and 90 N back, and the robot fell backwards).
    """
    cfg, nv = ctrl.cfg, NV_ROBOT
    Gs, hs = [], []
    if cfg.joint_limits:
        qj, qdj = d.qpos[JOINTS_QPOS], d.qvel[JOINTS_QVEL]
        b_lo, b_hi = limit_bounds(ctrl, qj, qdj)
        for j in np.flatnonzero(b_lo > -cfg.limit_active):
            g = np.zeros(nv)
            g[6 + j] = -1.0
            Gs.append(g)
            hs.append(-b_lo[j])
        for j in np.flatnonzero(b_hi < cfg.limit_active):
            g = np.zeros(nv)
            g[6 + j] = 1.0
            Gs.append(g)
            hs.append(b_hi[j])
    a = TOUCHDOWN_RATE
    for k in (k for k in range(2) if k not in stance):
        fb = ctrl.feet[k]
        R = d.xmat[fb].reshape(3, 3)
        for p in ctrl.corners[k]:
            pw = d.xpos[fb] + R @ p
            if pw[2] > cfg.touchdown_zone:
                continue
            jp, _, bp, _ = ctrl._jac(d, fb, pw)
            zd = jp[2] @ d.qvel[:nv]
            bound = -a * (zd + cfg.touchdown_speed)  # a speed cap only: zdd >= -a (zd + v_max)
            Gs.append(-jp[2])
            hs.append(bp[2] - bound)
    if cfg.clearance_rate > 0 and ctrl.clear_pairs:
        G, h = clearance_rows(ctrl, d, seated=target.seated)
        Gs += G
        hs += h
    return np.array(Gs).reshape(-1, nv), np.array(hs)


def clearance_rows(ctrl, d, seated: bool = False) -> tuple[list, list]:
    """Rows that keep the legs off the objects (``ctrl.clear_pairs``: leg geom, object geom).

    For a pair closer than ``clearance + clearance_zone`` with signed distance ``d`` (``mj_geomDistance``),
    unit normal ``n`` from the leg's nearest point ``p`` to the object's, ``dd = -n^T J_p qd`` and
    ``ddd = -n^T (J_p qdd + Jdot_p qd)`` (the object taken at rest), the same critically damped barrier as
    the joint ranges, ``ddd + 2 a dd + a^2 max(d - clearance, 0) >= 0`` (``a`` = ``clearance_rate``):
    ``n^T J_p qdd <= -n^T Jdot_p qd + 2 a dd + a^2 max(d - clearance, 0)``. Inside the clearance (a leg
    that starts next to the object) the row only brakes the approach: pushing it out kicked the robot over.
    While ``seated`` the hips may rest on an object (their pairs get no row): the seat carries the thighs."""
    cfg, m = ctrl.cfg, ctrl.m
    a, reach = cfg.clearance_rate, cfg.clearance + cfg.clearance_zone
    Gs, hs = [], []
    fromto = np.zeros(6)
    for g, o in ctrl.clear_pairs:
        if seated and g in ctrl.hip_geoms:
            continue
        if np.linalg.norm(d.geom_xpos[g] - d.geom_xpos[o]) - m.geom_rbound[g] - m.geom_rbound[o] > reach:
            continue
        dist = mujoco.mj_geomDistance(m, d, g, o, reach, fromto)
        if dist >= reach:
            continue
        n = fromto[3:] - fromto[:3]
        nn = np.linalg.norm(n)
        if nn < 1e-9:
            continue
        n = n / nn if dist >= 0 else -n / nn
        jp, _, bp, _ = ctrl._jac(d, int(m.geom_bodyid[g]), fromto[:3].copy())
        dd = -n @ (jp @ d.qvel[:NV_ROBOT])
        Gs.append(n @ jp)
        hs.append(-n @ bp + 2 * a * dd + a * a * max(dist - cfg.clearance, 0.0))
    return Gs, hs


def limit_bounds(ctrl, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint-acceleration bounds ``b_lo <= qdd <= b_hi`` (29,) that keep each joint inside its range.

    With ``l = q_lo + m`` (``m`` = ``limit_margin``) the distance ``h = q - l`` obeys the second-order
    barrier ``hdd + 2 z a hd + a^2 h >= 0`` (``a`` = ``limit_rate``, ``z`` = ``limit_zeta``): with
    ``z = 1`` a critically damped approach that never crosses ``h = 0`` from ``h >= 0, hd + a h >= 0``
    and pulls a joint already past ``l`` back with the same dynamics (``z < 1`` brakes later and may
    overshoot into the margin). So ``qdd >= -2 z a qd - a^2 (q - l)``, symmetrically at the upper end.
    Far from a limit the bound is far below what any task asks and the row is left out of the QP."""
    a, c = ctrl.cfg.limit_rate, 2 * ctrl.cfg.limit_zeta * ctrl.cfg.limit_rate
    lo, hi = ctrl.q_lo + ctrl.cfg.limit_margin, ctrl.q_hi - ctrl.cfg.limit_margin
    return -c * qd - a * a * (q - lo), -c * qd - a * a * (q - hi)
