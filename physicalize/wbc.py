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
``tau_ext``: the object is a free body moved only by contact; the object loop below adds its own
rows). Tasks ``a_i*`` are PD laws with feed-forward: centre of mass, pelvis and torso orientation, swing-foot
poses, hand positions and a posture from the reference. Stance feet hold still with a damping term and are
turned back flat (``a_foot* = -k_v v - k_p [0; roll/pitch error]``), which keeps a foot from rolling onto its edge.
Hand tasks track a point of each hand (``Target.hand_offset``) with per-hand weights. A hand that holds an
object (:mod:`physicalize.grasp`) does so in one of two ways, chosen per gain set (``WBCConfig.object_loop``):

* **the object loop** (:mod:`physicalize.object_loop`): the held object's contact forces (every measured
  hand-object contact, the support's contacts while the reference rests it) and its acceleration are QP
  variables, bound by its Newton-Euler equation, with a PD task from its **measured** pose to its reference;
  the robot feels the hands' forces through ``-J^T f`` in the rows above. A hand in contact moves with the
  object's material point under it along its face (``w_stick``) and presses along the normal towards its
  reference point carried onto the measured object pose; that goal is pressed in by the integral of the
  normal-force error, the QP's force of the last step against the force MuJoCo's soft contact delivered
  (``press_gain``): the loop closed on the measured contact force.
* **the open loop**: the force planned offline from the reference track (:mod:`physicalize.grasp_force`) enters
  as the reaction ``-J_k^T f_k`` in ``tau_ext`` in place of that object's measured contacts on the forearm; a
  held object that lags its reference position by ``e`` with ``|e| > hand_lead`` moves the hand target by
  ``e (1 - hand_lead/|e|)`` (the hands stay on the object and push it back with a bounded PD force).

Support comes from the schedule corrected by the simulation's contacts, and the swing foot lands
where the divergent component of motion ``xi = c + c_dot / omega`` can be caught
(:meth:`physicalize.stepping.Stepping.adapt`: late and early touchdowns, capture-point step adjustment,
the CoM target following the footholds taken); off while a seat or an object carries part of the weight.
The QP's rows are assembled in :mod:`physicalize.wbc_qp` (cost, equalities, friction and torque bounds)
and :mod:`physicalize.wbc_rows` (soft rows).

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
from physicalize.object_loop import ObjectLoop, contact_frame
from physicalize.seat import SupportPoint
from physicalize.stepping import Stepping
from physicalize.target import Solution, Target
from physicalize.wbc_config import WBCConfig
from physicalize.wbc_qp import (
    UP_FRAME,
    Costs,
    equality_rows,
    friction_rows,
    seated_load_rows,
    torque_map,
    with_slack,
)
from pipeline.contacts import ContactSets, robot_contacts
from pipeline.robot import (
    G1_JOINT_NAMES,
    HAND_BODIES,
    JOINTS_QPOS,
    JOINTS_QVEL,
    NUM_JOINTS,
    NV_ROBOT,
    ActuatorProfile,
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

ComState = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # (c, J_com, Jdot_com qd, c_dot)


class WholeBodyController:
    """The QP above on a compiled scene (the robot must be the model's first tree: dofs 0..34)."""

    def __init__(self, model: mujoco.MjModel, profile: ActuatorProfile, config: WBCConfig = WBCConfig()):
        self.m, self.profile, self.cfg = model, profile, config
        self.contacts = ContactSets.of(model)  # what the seat and stepping helpers know of the robot
        self.pelvis, self.torso = model.body("pelvis").id, model.body("torso_link").id
        self.feet, self.corners, self.floor = self.contacts.feet, self.contacts.corners, self.contacts.floor
        self.hands = [model.body(b).id for b in HAND_BODIES]
        self.grip_geoms = [
            {g for link in GRIP_LINKS for g in link_collision_geoms(model, f"{side}_{link}")}
            for side in ("left", "right")
        ]
        self.robot_bodies, self.robot_geoms = self.contacts.bodies, self.contacts.robot_geoms
        self.robot_mass = float(sum(model.body_mass[b] for b in self.robot_bodies))
        own = sorted(self.robot_geoms)  # in id order: the order of the clearance rows
        # never seat contacts
        self.unseated_geoms = {g for g in own if model.geom_bodyid[g] in self.feet} | set().union(*self.grip_geoms)
        legs = [
            g
            for g in own
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
        self._press = np.zeros(2)  # each holding hand's goal pressed into the object (the contact force loop)

    def state(self) -> tuple:
        """The controller's own state between control steps (the stepping's landing shifts, the hands' press): with
        :meth:`set_state`, a rollout restored to a frame continues exactly (:class:`physicalize.rollout.Tracker`)."""
        return self.stepping.landing_shift.copy(), self._press.copy()

    def set_state(self, state: tuple) -> None:
        self.stepping.landing_shift, self._press = state[0].copy(), state[1].copy()

    # --- kinematics helpers ---------------------------------------------------------------------
    def _jac(self, d, body: int, point: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Jp, Jr, Jdot_p qd, Jdot_r qd) of a point on ``body`` (robot columns only)."""
        jp, jr = np.zeros((3, self.m.nv)), np.zeros((3, self.m.nv))
        mujoco.mj_jac(self.m, d, jp, jr, point, body)
        dp, dr = np.zeros((3, self.m.nv)), np.zeros((3, self.m.nv))
        mujoco.mj_jacDot(self.m, d, dp, dr, point, body)
        qd = d.qvel
        return jp[:, :NV_ROBOT], jr[:, :NV_ROBOT], dp @ qd, dr @ qd

    def com(self, d) -> ComState:
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
        m, tau = self.m, np.zeros(NV_ROBOT)
        for c in robot_contacts(m, d, self.robot_geoms):
            if c.other == self.floor and m.geom_bodyid[c.geom] in self.feet:
                continue
            if other_body is not None and (c.geom not in robot_geoms or m.geom_bodyid[c.other] != other_body):
                continue
            f = c.force()
            jp = np.zeros((3, m.nv))
            mujoco.mj_jac(m, d, jp, None, c.pos, m.geom_bodyid[c.geom])
            tau += jp[:, :NV_ROBOT].T @ f
        return tau

    # --- the QP ---------------------------------------------------------------------------------
    def solve(self, d, target: Target) -> Solution:
        """One control step from the current state ``d`` (after ``mj_forward``): the tasks' cost in the
        order below (the sums' order fixes the solution's last bits), the rows, the QP, and the posture
        PD with gravity compensation of the current state where the QP has no solution."""
        cfg, nv = self.cfg, NV_ROBOT
        com = self.com(d)
        target, tau_ext, seats = self._support(d, target, com)
        stance = [k for k in range(2) if target.stance[k]]
        qd = d.qvel[:nv]
        mujoco.mj_fullM(self.m, d, self._M)
        M, h = self._M[:nv, :nv], d.qfrc_bias[:nv] - d.qfrc_passive[:nv]
        loop = None
        if target.held is not None and cfg.object_loop is not None:
            loop = ObjectLoop.measure(self.m, d, target.held, self.grip_geoms, self.floor)
        nf_robot = 12 * len(stance) + 3 * len(seats)
        cost = Costs(nv, nf_robot + (loop.nf if loop is not None else 0))
        self._com_task(cost, target, com)
        self._orientation_tasks(cost, d, target, qd)
        feet = self._foot_tasks(cost, d, target, qd)
        tau_ext = self._hand_tasks(cost, d, target, qd, tau_ext, loop, nv + nf_robot)
        self._posture_task(cost, d, target, qd)
        cost.regularize(cfg.w_qdd, cfg.w_force)
        Jc = self._contact_jacobians(cost, d, stance, seats, qd)
        if loop is not None:
            Jc = np.vstack([Jc, loop.robot_jacobians(self.m, d)])
            for Ao, bo, wo in loop.tasks(nv + nf_robot, cost.n, cfg.object_loop):
                cost.rows(Ao, bo, wo)
        A, b = equality_rows(M, h, tau_ext, Jc, [feet[k] for k in stance], cost.nf)
        G, hv = friction_rows([UP_FRAME] * (4 * len(stance)) + [sp.frame for sp in seats], cfg.mu, nv, cost.n)
        if seats and cfg.seated_foot_load > 0:  # seated, each stance foot still carries a share of the weight
            Gf, hf = seated_load_rows(len(stance), nv, cost.n, cfg.seated_foot_load * self.robot_mass * 9.81)
            G, hv = G + [Gf], hv + [hf]
        if loop is not None:
            Ao, bo, Go, ho = loop.rows(nv + nf_robot, cost.n, cfg.object_loop)
            A, b, G, hv = np.vstack([A, Ao]), np.concatenate([b, bo]), G + [Go], hv + [ho]
        Tq, ta = torque_map(M, h, tau_ext, Jc)  # tau = Tq x + ta
        G += [Tq, -Tq]
        hv += [cfg.effort_scale * self.effort - ta, cfg.effort_scale * self.effort + ta]
        Gs, hs = wbc_rows.soft_rows(self, d, target, stance)
        P, q, G, hv, A = with_slack(cost, np.vstack(G), np.concatenate(hv), A, Gs, hs, cfg.w_limit_slack)
        x = solve_qp(P, q, G, hv, A, b, solver="daqp")
        ok = x is not None
        x = x[: cost.n] if ok else self._fallback(d, target, cost.n)
        self._remember_press(loop, x, nv + nf_robot, ok)
        qdd, f = x[:nv], x[nv : nv + nf_robot]
        tau = np.clip(Tq @ x + ta, -self.effort, self.effort)
        shift = self.stepping.landing_shift.copy()
        return Solution(qdd, f.reshape(-1, 3), tau, self.action(d, qdd, tau), ok, target.stance, shift)

    def _support(self, d, target: Target, com: ComState) -> tuple[Target, np.ndarray, list[SupportPoint]]:
        """``(target, tau_ext, seats)``: the target with the stepping logic's support and footholds (unless
        other contacts carry ``other_support`` of the weight: sitting, leaning), the measured external
        generalized force and the seat's support points, whose measured contacts leave ``tau_ext``."""
        tau_ext = self.external_forces(d)
        supported = tau_ext[2] > self.cfg.other_support * self.robot_mass * 9.81  # sitting, leaning: no stepping logic
        if not supported:
            target = self.stepping.adapt(self.contacts, self.cfg, d, target, com[0], com[3])
        seats = seat.support_points(self.contacts, d, self.unseated_geoms) if target.seated else []
        for sp in seats:  # the QP chooses the seat's force (it is no longer a measured given)
            tau_ext = tau_ext - sp.tau
        return target, tau_ext, seats

    def _com_task(self, cost: Costs, target: Target, com: ComState) -> None:
        """``c_dd* = c_dd_ref + k_p (c_ref - c) + k_d (c_dot_ref - c_dot)``, per world axis."""
        cfg, (c, Jc, bc, cd) = self.cfg, com
        kp, kd = np.array(cfg.com_kp), np.array(cfg.com_kd)
        cost.task(Jc, target.com_acc + kp * (target.com - c) + kd * (target.com_vel - cd) - bc, cfg.w_com)

    def _orientation_tasks(self, cost: Costs, d, target: Target, qd: np.ndarray) -> None:
        """Pelvis and torso: ``w_dot* = k_p log(R_ref R^T) - k_d w``."""
        cfg = self.cfg
        for body, w, bid in ((self.pelvis, cfg.w_pelvis, 0), (self.torso, cfg.w_torso, 1)):
            Rref = self._ref_rotation(target, bid)
            _, Jr, _, br = self._jac(d, body, d.xpos[body])
            err = orientation_error(Rref, d.xmat[body].reshape(3, 3))
            cost.task(Jr, cfg.orient_kp * err - cfg.orient_kd * (Jr @ qd) - br, w)

    def _foot_tasks(self, cost: Costs, d, target: Target, qd: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Swing feet's pose tasks (PD with the reference's feed-forward); returns each stance foot's
        equality row ``(J (6, 35), a* - Jdot qd)`` with ``a* = -k_v v - k_p [0; roll/pitch error]``."""
        cfg, stance_rows = self.cfg, {}
        for k in range(2):
            fb = self.feet[k]
            Jp, Jr, bp, br = self._jac(d, fb, d.xpos[fb])
            J6, b6 = np.vstack([Jp, Jr]), np.concatenate([bp, br])
            v6 = J6 @ qd
            R = d.xmat[fb].reshape(3, 3)
            if target.stance[k]:
                a = -cfg.stance_kv * v6
                a[3:] += cfg.stance_flat_kp * orientation_error(_flat_of(R), R)
                stance_rows[k] = (J6, a - b6)
            else:
                ep = target.foot_pos[k] - d.xpos[fb]
                er = orientation_error(quat_mat(target.foot_quat[k]), R)
                a = np.concatenate(
                    [
                        target.foot_acc[k] + cfg.foot_kp * ep + cfg.foot_kd * (target.foot_vel[k] - v6[:3]),
                        cfg.orient_kp * er - cfg.orient_kd * v6[3:],
                    ]
                )
                cost.task(J6, a - b6, cfg.w_swing)
        return stance_rows

    def _hand_tasks(
        self, cost: Costs, d, target: Target, qd: np.ndarray, tau_ext: np.ndarray, loop: ObjectLoop | None, col0: int
    ) -> np.ndarray:
        """Hand point (and orientation) tasks; returns ``tau_ext`` without the held object's measured contacts on
        the holding forearms (their forces are the loop's variables, or the open loop's planned reaction
        ``-J^T f``). In the loop a holding hand's goal is its reference point carried to the measured object pose
        and pressed along the contact's inward normal by :attr:`_press`; in contact, rows move it with the object's
        material point under it (the normal row repeats the goal's PD, which the hand's own task also holds: the
        weighting the measurements were taken with). In the open loop its goal is :meth:`_led_goal`."""
        if target.hand_pos is None:
            return tau_ext
        cfg, z3 = self.cfg, np.zeros((2, 3))
        off = z3 if target.hand_offset is None else target.hand_offset
        hv = z3 if target.hand_vel is None else target.hand_vel
        ha = z3 if target.hand_acc is None else target.hand_acc
        touching = {} if loop is None else {hc.k: hc for hc in loop.hands}
        for k in range(2):
            hb = self.hands[k]
            p = d.xpos[hb] + d.xmat[hb].reshape(3, 3) @ off[k]
            Jp, Jr, bp, br = self._jac(d, hb, p)
            w = cfg.w_hand if target.hand_weight is None else float(target.hand_weight[k])
            holding = target.held is not None and bool(target.held.hands[k])
            if loop is not None and holding:
                press = None if k not in touching else self._press[k] * touching[k].normal
                goal, vel = loop.hand_goal(target.hand_pos[k], target.hand_vel[k], press)
                a = cfg.hold_kp * (goal - p) + cfg.hold_kd * (vel - Jp @ qd)
                if k in touching:  # sticks to the object along its face, presses along the normal
                    Ao, bo = loop.point_rows(p, col0, cost.n)
                    Ao[:, :NV_ROBOT] -= Jp
                    E = contact_frame(touching[k].normal)
                    slip = E[1:] @ (Jp @ qd - loop.point_velocity(p))
                    rhs = np.r_[E[0] @ a, -cfg.hold_kd * slip]
                    cost.rows(-E @ Ao, rhs + E @ (bo - bp), [w, cfg.w_stick, cfg.w_stick])
                    tau_ext = tau_ext - self.external_forces(d, self.grip_geoms[k], target.held.body)
                cost.task(Jp, ha[k] + a - bp, w)
            elif holding:  # the open loop: the planned force, the hands on the reference object's track
                goal = self._led_goal(d, target, k)
                a = ha[k] + cfg.hold_kp * (goal - p) + cfg.hold_kd * (hv[k] - Jp @ qd)
                cost.task(Jp, a - bp, w)
                tau_ext = tau_ext - self.external_forces(d, self.grip_geoms[k], target.held.body)
                tau_ext = tau_ext - Jp.T @ target.hand_force[k]
            else:
                a = ha[k] + cfg.hand_kp * (target.hand_pos[k] - p) + cfg.hand_kd * (hv[k] - Jp @ qd)
                cost.task(Jp, a - bp, w)
            if target.hand_rot is not None and target.hand_rot_weight[k] > 0:
                err = orientation_error(target.hand_rot[k], d.xmat[hb].reshape(3, 3))
                cost.task(Jr, cfg.orient_kp * err - cfg.orient_kd * (Jr @ qd) - br, float(target.hand_rot_weight[k]))
        return tau_ext

    def _remember_press(self, loop: ObjectLoop | None, x: np.ndarray, col0: int, ok: bool) -> None:
        """Close the loop on the measured contact force (:meth:`ObjectLoop.normal_force_error`): ``_press[k] += k_f
        e_k dt``, clipped to ``[-press_max, press_max]``; reset for a hand that holds nothing."""
        held = np.zeros(2, bool) if loop is None else loop.held.hands.astype(bool)
        if loop is not None and ok:
            self._press += self.cfg.press_gain * loop.normal_force_error(x, col0) * CONTROL_DT
        self._press = np.where(held, np.clip(self._press, -self.cfg.press_max, self.cfg.press_max), 0.0)

    def _led_goal(self, d, target: Target, k: int) -> np.ndarray:
        """The open loop's goal of holding hand ``k``: its reference point, following a held object whose body origin
        lags its reference by ``e`` beyond ``hand_lead`` by ``e (1 - hand_lead / |e|)`` (pulling it back with a
        bounded push)."""
        held = target.held
        dev = d.xpos[held.body] - held.motion.pos[held.t]
        nd = float(np.linalg.norm(dev))
        goal = target.hand_pos[k]
        return goal + dev * (1.0 - self.cfg.hand_lead / nd) if nd > self.cfg.hand_lead else goal

    def _posture_task(self, cost: Costs, d, target: Target, qd: np.ndarray) -> None:
        """Joint PD towards the reference posture, with its acceleration as feed-forward."""
        cfg, nv = self.cfg, NV_ROBOT
        qj, qdj = d.qpos[JOINTS_QPOS], qd[JOINTS_QVEL]
        Jq = np.zeros((NUM_JOINTS, nv))
        Jq[:, JOINTS_QVEL] = np.eye(NUM_JOINTS)
        cost.task(
            Jq,
            target.qacc[JOINTS_QVEL]
            + cfg.posture_kp * (target.qpos[JOINTS_QPOS] - qj)
            + cfg.posture_kd * (target.qvel[JOINTS_QVEL] - qdj),
            cfg.w_posture,
        )

    def _contact_jacobians(
        self, cost: Costs, d, stance: list[int], seats: list[SupportPoint], qd: np.ndarray
    ) -> np.ndarray:
        """(n_points, 35) world-frame Jacobians of the contact points: the stance feet's sole corners, then
        the seat's points. A seat point is held like a stance foot, softly (its task added here; held hard
        with the feet and the torque bounds, the QP was infeasible)."""
        cfg, Jc = self.cfg, [np.zeros((0, NV_ROBOT))]
        for k in stance:
            fb = self.feet[k]
            R = d.xmat[fb].reshape(3, 3)
            for p in self.corners[k]:
                Jc.append(self._jac(d, fb, d.xpos[fb] + R @ p)[0])
        for sp in seats:
            jp, _, bp, _ = self._jac(d, sp.body, sp.point)
            Jc.append(jp)
            cost.task(jp, -cfg.stance_kv * (jp @ qd) - bp, cfg.w_seat)
        return np.vstack(Jc)

    def _fallback(self, d, target: Target, n: int) -> np.ndarray:
        """``x`` when the QP has no solution: the posture PD (with gravity compensation of the current state
        through the torque map), no contact force."""
        x = np.zeros(n)
        qj, qdj = d.qpos[JOINTS_QPOS], d.qvel[:NV_ROBOT][JOINTS_QVEL]
        x[JOINTS_QVEL] = self.cfg.posture_kp * (target.qpos[JOINTS_QPOS] - qj) - self.cfg.posture_kd * qdj
        return x

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
