"""A training-free whole-body QP controller for the G1 in MuJoCo (the teacher's base tracker).

Every control step (50 Hz) it solves one quadratic program over the robot's generalized
accelerations ``qdd`` (35: free root + 29 joints) and the 3-D contact forces ``f`` at the four
sole corners of each stance foot and, while seated, at the seat's support points (:mod:`physicalize.seat`)::

    min   sum_i w_i || J_i qdd + Jdot_i qd - a_i* ||^2  +  w_q ||qdd||^2  +  w_f ||f||^2
    s.t.  M_u qdd + h_u = J_{c,u}^T f + tau_ext,u      (floating base, 6 rows: no root actuation)
          J_foot qdd + Jdot_foot qd = a_foot*           (stance feet, 6 rows each; seat points 3 rows, alike)
          |f.t_i| <= mu f.n / sqrt 2,  f.n >= 0        (friction pyramids inscribed in the cones, per point)
          -e tau_max <= M_a qdd + h_a - J_{c,a}^T f - tau_ext,a <= e tau_max   (e = effort_scale, 0.95)
          G qdd - s <= h,  s >= 0,  + w_s ||s||^2       (soft rows: joint ranges, touchdown, legs off objects)

``M`` and ``h = qfrc_bias - qfrc_passive`` come from the simulation's own model (so the held
object's inertia is not in ``M``, but its measured contact forces on the robot are in
``tau_ext``: the object is a free body moved only by contact). Tasks ``a_i*`` are PD laws with
feed-forward: centre of mass, pelvis and torso orientation, swing-foot poses, hand positions and a
posture from the reference. Stance feet hold still with a damping term and are turned back flat
(``a_foot* = -k_v v - k_p [0; roll/pitch error]``), which keeps a foot from rolling onto its edge.
Hand tasks track a point of each hand (``Target.hand_offset``) with per-hand weights and, while a hand
holds an object (:mod:`physicalize.grasp`), the planned force ``f_k`` it applies enters as the
reaction ``-J_k^T f_k`` in ``tau_ext`` in place of that object's measured contacts on the forearm; a held
object that lags its reference position by ``e`` with ``|e| > hand_lead`` moves the hand target by
``e (1 - hand_lead/|e|)`` (the hands stay on the object and push it back with a bounded PD force instead
of running ahead and pushing the robot off its feet).

Support comes from the schedule corrected by the simulation's contacts, and the swing foot lands
where the divergent component of motion ``xi = c + c_dot / omega`` can be caught
(:meth:`physicalize.stepping.Stepping.adapt`:
late and early touchdowns, capture-point step adjustment, the CoM target following the footholds
taken); off while a seat or an object carries part of the weight.

The joint torques ``tau = M_a qdd + h_a - J_{c,a}^T f - tau_ext,a`` become PD position targets held
for the control period ``T`` (4 physics steps): ``q* = q_m + (tau + k_d qd_m) / k_p`` at the
predicted mid-hold state ``q_m = q + qd T/2 + qdd T^2/8``, ``qd_m = qd + qdd T/2``; targets are not
clipped to the joint range (the actuators clip torque, the joints have their limits).
"""

from __future__ import annotations

import mujoco
import numpy as np
from qpsolvers import solve_qp

from physicalize import seat, wbc_rows
from physicalize.stepping import Stepping
from physicalize.target import Solution, Target
from physicalize.wbc_config import WBCConfig
from pipeline.robot import (
    FOOT_BODIES,
    G1_JOINT_NAMES,
    HAND_BODIES,
    JOINTS_QPOS,
    JOINTS_QVEL,
    NUM_JOINTS,
    NV_ROBOT,
    ActuatorProfile,
    sole_corners,
)
from pipeline.rotations import orientation_error, quat_mat
from pipeline.scene import link_collision_geoms

GRIP_LINKS = (
    "elbow_link",
    "wrist_roll_link",
    "wrist_pitch_link",
    "wrist_yaw_link",
)  # forearm and hand: a held object's contacts on them are planned
CONTROL_DT = 0.02
CLEAR_LINKS = ("hip_roll", "hip_yaw", "knee", "ankle_pitch")  # leg links whose contact with an object is never planned


class WholeBodyController:
    """The QP above on a compiled scene (the robot must be the model's first tree: dofs 0..34)."""

    def __init__(self, model: mujoco.MjModel, profile: ActuatorProfile, config: WBCConfig = WBCConfig()):
        self.m, self.profile, self.cfg = model, profile, config
        self.pelvis, self.torso = model.body("pelvis").id, model.body("torso_link").id
        self.feet = [model.body(b).id for b in FOOT_BODIES]
        self.hands = [model.body(b).id for b in HAND_BODIES]
        self.grip_geoms = [
            {g for link in GRIP_LINKS for g in link_collision_geoms(model, f"{side}_{link}")}
            for side in ("left", "right")
        ]
        self.corners = np.stack([sole_corners(model, b) for b in FOOT_BODIES])
        self.robot_bodies = [b for b in range(1, model.nbody) if model.body_rootid[b] == self.pelvis]
        self.robot_mass = float(sum(model.body_mass[b] for b in self.robot_bodies))
        self.robot_geoms = {g for g in range(model.ngeom) if model.geom_bodyid[g] in set(self.robot_bodies)}
        self.floor = model.geom("floor").id
        self.unseated_geoms = {g for g in self.robot_geoms if model.geom_bodyid[g] in self.feet} | set().union(
            *self.grip_geoms
        )  # never seat contacts
        legs = [
            g
            for g in self.robot_geoms
            if model.geom_contype[g] and any(k in model.body(model.geom_bodyid[g]).name for k in CLEAR_LINKS)
        ]
        objects = [
            g
            for g in range(model.ngeom)
            if model.geom_contype[g] and model.geom_bodyid[g] and g not in self.robot_geoms
        ]
        self.clear_pairs = [(g, o) for g in legs for o in objects]
        self.hip_geoms = {g for g in legs if "hip" in model.body(model.geom_bodyid[g]).name}
        self.effort = profile.effort_limit
        self.q_lo, self.q_hi = model.jnt_range[[model.joint(j).id for j in G1_JOINT_NAMES]].T.copy()
        self._M = np.zeros((model.nv, model.nv))
        self.stepping = Stepping(CONTROL_DT)  # capture-point shift of each foot's last landing (controller state)
        self._jp, self._jr = np.zeros((3, model.nv)), np.zeros((3, model.nv))

    # --- kinematics helpers ---------------------------------------------------------------------
    def _jac(self, d, body: int, point: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Jp, Jr, Jdot_p qd, Jdot_r qd) of a point on ``body`` (robot columns only)."""
        jp, jr = np.zeros((3, self.m.nv)), np.zeros((3, self.m.nv))
        mujoco.mj_jac(self.m, d, jp, jr, point, body)
        dp, dr = np.zeros((3, self.m.nv)), np.zeros((3, self.m.nv))
        mujoco.mj_jacDot(self.m, d, dp, dr, point, body)
        qd = d.qvel
        return jp[:, :NV_ROBOT], jr[:, :NV_ROBOT], dp @ qd, dr @ qd

    def com(self, d) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(c, J_com, Jdot_com qd, c_dot) of the robot (requires mj_forward's position/velocity stages)."""
        J = np.zeros((3, self.m.nv))
        mujoco.mj_jacSubtreeCom(self.m, d, J, self.pelvis)
        bias = np.zeros(3)
        dp = np.zeros((3, self.m.nv))
        for b in self.robot_bodies:
            mujoco.mj_jacDot(self.m, d, dp, None, d.xipos[b], b)
            bias += self.m.body_mass[b] * (dp @ d.qvel)
        J = J[:, :NV_ROBOT]
        return d.subtree_com[self.pelvis].copy(), J, bias / self.robot_mass, J @ d.qvel[:NV_ROBOT]

    def external_forces(self, d, robot_geoms: set[int] | None = None, other_body: int | None = None) -> np.ndarray:
        """Generalized force (35,) on the robot from every contact except its own feet on the floor
        and its self-collisions (objects, seats, other links on the floor), measured in the simulation;
        only those of ``robot_geoms`` with ``other_body`` when given."""
        tau = np.zeros(NV_ROBOT)
        f6 = np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            g1, g2 = c.geom1, c.geom2
            r1, r2 = g1 in self.robot_geoms, g2 in self.robot_geoms
            if r1 == r2:
                continue
            rg, other = (g1, g2) if r1 else (g2, g1)
            if other == self.floor and self.m.geom_bodyid[rg] in self.feet:
                continue
            if other_body is not None and (rg not in robot_geoms or self.m.geom_bodyid[other] != other_body):
                continue
            mujoco.mj_contactForce(self.m, d, i, f6)
            f = c.frame.reshape(3, 3).T @ f6[:3]  # on geom2, world frame
            f = f if rg == g2 else -f
            jp = np.zeros((3, self.m.nv))
            mujoco.mj_jac(self.m, d, jp, None, c.pos, self.m.geom_bodyid[rg])
            tau += jp[:, :NV_ROBOT].T @ f
        return tau

    # --- the QP ---------------------------------------------------------------------------------
    def solve(self, d, target: Target) -> Solution:
        """One control step from the current state ``d`` (after ``mj_forward``)."""
        m, cfg = self.m, self.cfg
        nv = NV_ROBOT
        tau_ext = self.external_forces(d)
        supported = tau_ext[2] > cfg.other_support * self.robot_mass * 9.81  # sitting, leaning: no stepping logic
        target = self.stepping.adapt(self, d, target) if cfg.contact_stance and not supported else target
        stance = [k for k in range(2) if target.stance[k]]
        seats = seat.support_points(self, d, self.unseated_geoms) if target.seated else []
        for sp in seats:  # the QP chooses the seat's force (it is no longer a measured given)
            tau_ext = tau_ext - sp.tau
        nf = 12 * len(stance) + 3 * len(seats)
        n = nv + nf
        qd = d.qvel[:nv]
        mujoco.mj_fullM(m, d, self._M)
        M = self._M[:nv, :nv]
        h = d.qfrc_bias[:nv] - d.qfrc_passive[:nv]

        P = np.zeros((n, n))
        q = np.zeros(n)

        def task(J: np.ndarray, b: np.ndarray, w) -> None:
            w = np.broadcast_to(np.asarray(w, dtype=float), b.shape)[:, None]
            P[:nv, :nv] += J.T @ (w * J)
            q[:nv] -= J.T @ (w[:, 0] * b)

        c, Jc, bc, cd = self.com(d)
        kp, kd = np.array(cfg.com_kp), np.array(cfg.com_kd)
        task(Jc, target.com_acc + kp * (target.com - c) + kd * (target.com_vel - cd) - bc, cfg.w_com)
        for body, w, bid in ((self.pelvis, cfg.w_pelvis, 0), (self.torso, cfg.w_torso, 1)):
            Rref = self._ref_rotation(target, bid)
            _, Jr, _, br = self._jac(d, body, d.xpos[body])
            err = orientation_error(Rref, d.xmat[body].reshape(3, 3))
            task(Jr, cfg.orient_kp * err - cfg.orient_kd * (Jr @ qd) - br, w)
        Jfeet = {}
        for k in range(2):
            fb = self.feet[k]
            Jp, Jr, bp, br = self._jac(d, fb, d.xpos[fb])
            J6, b6 = np.vstack([Jp, Jr]), np.concatenate([bp, br])
            v6 = J6 @ qd
            R = d.xmat[fb].reshape(3, 3)
            if target.stance[k]:
                flat = _flat_of(R)
                a = -cfg.stance_kv * v6
                a[3:] += cfg.stance_flat_kp * orientation_error(flat, R)
                Jfeet[k] = (J6, a - b6)
            else:
                ep = target.foot_pos[k] - d.xpos[fb]
                er = orientation_error(quat_mat(target.foot_quat[k]), R)
                a = np.concatenate(
                    [
                        cfg.swing_ff * target.foot_acc[k]
                        + cfg.foot_kp * ep
                        + cfg.foot_kd * (target.foot_vel[k] - v6[:3]),
                        cfg.orient_kp * er - cfg.orient_kd * v6[3:],
                    ]
                )
                task(J6, a - b6, cfg.w_swing)
        if target.hand_pos is not None:  # hand point tasks; a held object's planned reaction -J^T f in tau_ext
            z3 = np.zeros((2, 3))
            off = z3 if target.hand_offset is None else target.hand_offset
            hv = z3 if target.hand_vel is None else target.hand_vel
            ha = z3 if target.hand_acc is None else target.hand_acc
            for k in range(2):
                hb = self.hands[k]
                p = d.xpos[hb] + d.xmat[hb].reshape(3, 3) @ off[k]
                Jp, Jr, bp, br = self._jac(d, hb, p)
                goal = target.hand_pos[k]
                holding = target.hand_hold_body is not None and target.hand_hold_body[k] >= 0
                kp, kd = (cfg.hold_kp, cfg.hold_kd) if holding else (cfg.hand_kp, cfg.hand_kd)
                if holding:  # follow a lagging object, pull it back at most hand_lead
                    dev = d.xpos[int(target.hand_hold_body[k])] - target.hand_hold_ref[k]
                    nd = float(np.linalg.norm(dev))
                    if nd > cfg.hand_lead:
                        goal = goal + dev * (1.0 - cfg.hand_lead / nd)
                a = ha[k] + kp * (goal - p) + kd * (hv[k] - Jp @ qd)
                task(Jp, a - bp, cfg.w_hand if target.hand_weight is None else float(target.hand_weight[k]))
                if target.hand_rot is not None and target.hand_rot_weight[k] > 0:
                    err = orientation_error(target.hand_rot[k], d.xmat[hb].reshape(3, 3))
                    task(Jr, cfg.orient_kp * err - cfg.orient_kd * (Jr @ qd) - br, float(target.hand_rot_weight[k]))
                if target.hand_force is not None:
                    if target.hand_object is not None and target.hand_object[k] >= 0:
                        tau_ext = tau_ext - self.external_forces(d, self.grip_geoms[k], int(target.hand_object[k]))
                    tau_ext = tau_ext - Jp.T @ target.hand_force[k]
        qj, qdj = d.qpos[JOINTS_QPOS], qd[JOINTS_QVEL]
        Jq = np.zeros((NUM_JOINTS, nv))
        Jq[:, JOINTS_QVEL] = np.eye(NUM_JOINTS)
        task(
            Jq,
            target.qacc[JOINTS_QVEL]
            + cfg.posture_kp * (target.qpos[JOINTS_QPOS] - qj)
            + cfg.posture_kd * (target.qvel[JOINTS_QVEL] - qdj),
            cfg.w_posture,
        )
        P[:nv, :nv] += cfg.w_qdd * np.eye(nv)
        P[nv:, nv:] += cfg.w_force * np.eye(nf)

        Jc = [
            np.zeros((0, nv))
        ]  # contact point Jacobians (world frame): the stance feet's sole corners, then the seat's points
        for k in stance:
            fb = self.feet[k]
            R = d.xmat[fb].reshape(3, 3)
            for p in self.corners[k]:
                Jc.append(self._jac(d, fb, d.xpos[fb] + R @ p)[0])
        A, b = [], []
        for k in stance:
            A.append(np.hstack([Jfeet[k][0], np.zeros((6, nf))]))
            b.append(Jfeet[k][1])
        # a seat's support point is held like a stance foot, softly (held hard with the feet and the torque bounds, the
        # QP was infeasible)
        for sp in seats:
            jp, _, bp, _ = self._jac(d, sp.body, sp.point)
            Jc.append(jp)
            task(jp, -cfg.stance_kv * (jp @ qd) - bp, cfg.w_seat)
        Jc = np.vstack(Jc)
        A, b = np.vstack([np.hstack([M[:6], -Jc[:, :6].T])] + A), np.concatenate([-h[:6] + tau_ext[:6]] + b)
        mu = cfg.mu / np.sqrt(2.0)  # the pyramid inscribed in the cone: |f_t| <= mu f_n in every direction
        frames = [np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0]])] * (4 * len(stance)) + [sp.frame for sp in seats]
        G, hv = [], []
        if frames:
            Gc = np.zeros((5 * len(frames), n))
            for j, (fn, t1, t2) in enumerate(frames):
                Gc[5 * j : 5 * j + 5, nv + 3 * j : nv + 3 * j + 3] = [
                    t1 - mu * fn,
                    -t1 - mu * fn,
                    t2 - mu * fn,
                    -t2 - mu * fn,
                    -fn,
                ]
            G.append(Gc)
            hv.append(np.zeros(5 * len(frames)))
        if (
            seats and cfg.seated_foot_load > 0
        ):  # seated, each stance foot still carries a share of the weight (else the robot tipped back, feet in the air)
            Gf = np.zeros((len(stance), n))
            for s in range(len(stance)):
                Gf[s, nv + 12 * s + 2 : nv + 12 * s + 12 : 3] = -1.0
            G.append(Gf)
            hv.append(np.full(len(stance), -cfg.seated_foot_load * self.robot_mass * 9.81))
        Tq = np.hstack([M[JOINTS_QVEL], -Jc[:, JOINTS_QVEL].T])  # tau = Tq x + h_a - tau_ext_a
        ta = h[JOINTS_QVEL] - tau_ext[JOINTS_QVEL]
        G += [Tq, -Tq]
        hv += [cfg.effort_scale * self.effort - ta, cfg.effort_scale * self.effort + ta]
        G, hv = np.vstack(G), np.concatenate(hv)
        Gs, hs = wbc_rows.soft_rows(self, d, target, stance)
        ns = len(hs)
        if ns:  # soft rows  Gs qdd - s <= hs  with slack s >= 0 (weight w_limit_slack): the QP stays feasible
            Gl = np.zeros((2 * ns, n + ns))
            Gl[:ns, :nv] = Gs
            Gl[:ns, n:] = -np.eye(ns)
            Gl[ns:, n:] = -np.eye(ns)
            G = np.vstack([np.hstack([G, np.zeros((G.shape[0], ns))]), Gl])
            hv = np.concatenate([hv, hs, np.zeros(ns)])
            P = np.block([[P, np.zeros((n, ns))], [np.zeros((ns, n)), cfg.w_limit_slack * np.eye(ns)]])
            q = np.concatenate([q, np.zeros(ns)])
            A = np.hstack([A, np.zeros((A.shape[0], ns))])
        x = solve_qp(P, q, G, hv, A, b, solver="daqp")
        ok = x is not None
        if ok:
            x = x[:n]
        if not ok:  # fall back to the posture PD with gravity compensation of the current state
            x = np.zeros(n)
            x[JOINTS_QVEL] = cfg.posture_kp * (target.qpos[JOINTS_QPOS] - qj) - cfg.posture_kd * qdj
        qdd, f = x[:nv], x[nv:]
        tau = np.clip(Tq @ x + ta, -self.effort, self.effort)
        return Solution(qdd, f.reshape(-1, 3), tau, self.action(d, qdd, tau), ok)

    @staticmethod
    def _ref_rotation(target: Target, which: int) -> np.ndarray:
        return quat_mat(target.torso_quat if which == 1 and target.torso_quat is not None else target.qpos[3:7])

    def action(self, d, qdd: np.ndarray, tau: np.ndarray, hold: float = CONTROL_DT) -> np.ndarray:
        """PD joint targets that produce ``tau`` at the predicted mid-hold state."""
        q, qd, a = d.qpos[JOINTS_QPOS], d.qvel[JOINTS_QVEL], qdd[JOINTS_QVEL]
        qm = q + qd * hold / 2 + a * hold**2 / 8
        qdm = qd + a * hold / 2
        return qm + (tau + self.profile.kd * qdm) / self.profile.kp


def _flat_of(R: np.ndarray) -> np.ndarray:
    """The level rotation with ``R``'s heading (yaw of its x axis)."""
    yaw = np.arctan2(R[1, 0], R[0, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
