"""The held object inside the whole-body QP: its contact forces and acceleration as variables, bound by
its Newton-Euler equation and driven by feedback from its measured pose (:class:`ObjectLoop`, one per
control step, built from the simulation by :meth:`ObjectLoop.measure`).

Appended to the QP's ``x = (qdd, f)`` after the robot's own contact forces:

* ``f_h`` (3 per measured contact of a holding hand's forearm or hand with the object): that contact's force
  **on the object** at its point ``p_h`` and inward normal ``n_h``; friction pyramid of the hand-object friction
  (:func:`physicalize.wbc_qp.friction_rows`), ``0 <= f_h.n_h <= N_max``. The robot feels ``-f_h``: its contact
  Jacobian rows are ``-J_h``, so the floating base and the torques carry the object through the hands.
* ``f_s`` (3 per measured object-support contact, while the reference rests the object there): the support's
  force, normal up, ``f_s.n >= 0``; a friction pyramid where the reference keeps the object still; where it
  slides, kinetic friction against the contact point's motion, ``f_s,t = -mu f_s,n u`` (``u``: the point's
  measured horizontal velocity direction, the reference's while it is still at rest). The object-support
  friction is the scene's (:func:`physicalize.grasp_force.floor_friction`).
* ``a_o = (c_dd, w_dot)`` (6): the acceleration of the object's centre of mass and its angular
  acceleration (world).

Rows: Newton-Euler (equalities) ``m c_dd - sum f = m g + f_m``,
``I w_dot - sum (p - c) x f = t_m - w x I w`` (``f_m``, ``t_m``: the object's other measured contacts); the
support does not accelerate the object off itself or into itself (soft, ``w_support``:
``n.(c_dd - (p - c) x w_dot + w x (w x (p - c))) = 0``, and the tangential part too where it sticks):
unilateral forces that cannot hold the object still leave it tipping or sliding in the QP's model, which the
object task then weighs. Tasks: the object follows its reference by PD on its measured state,
``c_dd* = c_dd_ref + k_p (c_ref - c) + k_d (v_ref - v)``,
``w_dot* = w_dot_ref + k_p,r log(R_ref R^T) + k_d,r (w_ref - w)`` (weights ``w_object``, ``w_object_rot``);
a hand in contact moves with the object's point under it, ``J_h qdd + Jdot_h qd = c_dd - (p - c) x w_dot
+ w x (w x (p - c)) + PD`` (so the QP knows the hands must accelerate to accelerate the object); its goal
is its reference point carried from the reference object pose to the measured one
(:meth:`ObjectLoop.carry`).

MuJoCo's soft contacts do not deliver the QP's force exactly: the controller closes the loop on the measured
normal force (:class:`physicalize.wbc.WholeBodyController`: each hand's goal is pressed along the inward
normal by the integral of the normal-force error, :meth:`ObjectLoop.normal_force_error`).

Its size and cost (about 100 variables against the open loop's 78, twice its QP time) are in ``BENCHMARKS.md``."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from physicalize.object_motion import SLIDE_SPEED, ObjectMotion
from physicalize.wbc_qp import UP_FRAME, friction_rows
from pipeline.robot import NV_ROBOT
from pipeline.rotations import orientation_error

GRAVITY = np.array([0.0, 0.0, -9.81])


@dataclass(frozen=True)
class HeldObject:
    """What the controller is told at one step about the object the hands hold: its ``body``, which
    ``hands`` (2,) hold it, its reference motion at frame ``t`` of ``motion``, the hand-object and
    object-support frictions, and whether the hands squeeze it between them (:mod:`physicalize.grasp`)."""

    body: int
    hands: np.ndarray
    motion: ObjectMotion
    t: int
    mu_hand: float
    mu_support: float
    squeezed: bool = False


@dataclass(frozen=True)
class LoopGains:
    """The object loop's gains and weights (stiffness ``kp`` [1/s^2], damping ``kd`` [1/s], forces in N)."""

    kp: float = 100.0
    kd: float = 20.0
    kp_rot: float = 100.0
    kd_rot: float = 20.0
    w_object: float = 1000.0
    w_object_rot: float = 100.0
    w_support: float = 1000.0
    max_normal: float = 120.0  # N: a hand's contact point presses at most this hard
    # hands squeezing the object between them (HeldObject.squeezed) use mu / friction_margin in their pyramids and
    # press at least min_normal each: a grip at the QP's least force slips at the first disturbance (OMOMO's
    # sub3_largebox_003 dropped its box 30 cm at 5 s with 1.0 and 0 N, held it to the end with 2.0 and 15 N); a
    # push keeps the plain cone and no least force (the shoved default Push fell at 7.1 s with the margin, and its
    # box ran 30 cm ahead of its track with the least force)
    friction_margin: float = 2.0
    min_normal: float = 15.0


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0.0]])


def contact_frame(n: np.ndarray) -> np.ndarray:
    """(3, 3) rows ``(n, t1, t2)``: ``n`` and two tangents."""
    t1 = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    t1 /= np.linalg.norm(t1)
    return np.stack([n, t1, np.cross(n, t1)])


@dataclass
class GripPoint:
    """One measured contact of hand ``k`` (its forearm or hand) with the held object: the point, the inward
    normal, the robot body it is on, and the world-frame force the simulation measured on the object."""

    k: int
    point: np.ndarray
    normal: np.ndarray
    body: int
    measured: np.ndarray


@dataclass
class HandContact:
    """Hand ``k``'s contact with the held object: the indices of its :class:`GripPoint` s and their mean
    inward normal (weighted by the measured normal forces)."""

    k: int
    grips: list[int]
    normal: np.ndarray


@dataclass
class ObjectLoop:
    """One control step's object block (measured state, contacts, reference). Every MuJoCo contact of a hand
    with the object is a force variable (a capsule lying on a face touches at two points: their couple resists
    the object's turning about the face's normal, which one point force per hand cannot)."""

    held: HeldObject
    mass: float
    com: np.ndarray
    rot: np.ndarray
    vel: np.ndarray
    omega: np.ndarray
    inertia: np.ndarray  # (3, 3) world frame, about the centre of mass
    grips: list[GripPoint]
    hands: list[HandContact]
    support: list[np.ndarray]  # measured object-support contact points
    other: np.ndarray  # (6,) the object's other measured contacts: force, torque about the centre of mass
    sliding: np.ndarray | None  # (3,) horizontal direction of the support's kinetic friction, None: sticking

    @classmethod
    def measure(
        cls, m: mujoco.MjModel, d: mujoco.MjData, held: HeldObject, grip_geoms: list[set[int]], floor: int
    ) -> ObjectLoop:
        """The block at the state ``d`` (after ``mj_forward``): ``grip_geoms`` each hand's forearm and hand geoms."""
        b = held.body
        res = np.zeros(6)
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, b, res, 0)
        R = d.xmat[b].reshape(3, 3)  # the body frame (the reference's); the principal axes are ximat
        com, motion, t = d.xipos[b].copy(), held.motion, held.t
        grips: list[GripPoint] = []
        support, other = [], np.zeros(6)
        rests = bool(motion.rests[t])
        for i in range(d.ncon):
            g1, g2 = int(d.contact.geom1[i]), int(d.contact.geom2[i])
            b1, b2 = m.geom_bodyid[g1], m.geom_bodyid[g2]
            if b not in (b1, b2):
                continue
            mine, theirs = (g1, g2) if b1 == b else (g2, g1)
            f6 = np.zeros(6)
            mujoco.mj_contactForce(m, d, i, f6)
            frame = d.contact.frame[i].reshape(3, 3)
            sign = 1.0 if mine == g2 else -1.0  # the normal points from geom1 to geom2
            f_on_obj = frame.T @ f6[:3] * sign
            p = d.contact.pos[i].copy()
            k = next((k for k in range(2) if held.hands[k] and theirs in grip_geoms[k]), None)
            if k is not None:
                grips.append(GripPoint(k, p, frame[0] * sign, int(m.geom_bodyid[theirs]), f_on_obj))
            elif theirs == floor and rests:
                support.append(p)
            else:
                other += np.r_[f_on_obj, np.cross(p - com, f_on_obj)]
        hands = []
        for k in range(2):
            mine = [j for j, g in enumerate(grips) if g.k == k]
            if mine:
                n = sum(grips[j].normal * max(float(grips[j].measured @ grips[j].normal), 1e-3) for j in mine)
                hands.append(HandContact(k, mine, n / max(np.linalg.norm(n), 1e-9)))
        Ri = d.ximat[b].reshape(3, 3)
        inertia = Ri @ np.diag(m.body_inertia[b]) @ Ri.T
        sliding = None
        if support and motion.slides[t]:
            v = np.r_[res[3:5], 0.0]
            if np.linalg.norm(v) < SLIDE_SPEED:  # still at rest: it will slide the reference's way
                v = np.r_[motion.com_vel[t, :2], 0.0]
            sliding = v / max(np.linalg.norm(v), 1e-9)
        return cls(
            held,
            float(m.body_mass[b]),
            com,
            R,
            res[3:].copy(),
            res[:3].copy(),
            inertia,
            grips,
            hands,
            support,
            other,
            sliding,
        )

    # --- the QP block ------------------------------------------------------------------------------------
    @property
    def nf(self) -> int:
        """Variables of the block: the hands' forces, the support's, the object's acceleration."""
        return 3 * len(self.grips) + 3 * len(self.support) + 6

    def robot_jacobians(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        """(nf, 35) the rows of the block in the robot's contact Jacobian: ``-J_h`` (the robot feels the reaction
        of the hands' forces), zeros for the support's forces and the object's acceleration."""
        rows = []
        for g in self.grips:
            jp = np.zeros((3, m.nv))
            mujoco.mj_jac(m, d, jp, None, g.point, g.body)
            rows.append(-jp[:, :NV_ROBOT])
        rows.append(np.zeros((3 * len(self.support) + 6, NV_ROBOT)))
        return np.vstack(rows)

    def acc_cols(self, col0: int) -> slice:
        """The columns of ``a_o`` in ``x`` when the block starts at column ``col0``."""
        return slice(col0 + self.nf - 6, col0 + self.nf)

    def point_rows(self, p: np.ndarray, col0: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``(A (3, n), b (3,))`` with ``A x + b`` the acceleration of the object's material point at ``p``:
        ``c_dd - (p - c) x w_dot + w x (w x (p - c))``."""
        r, w = p - self.com, self.omega
        A = np.zeros((3, n))
        cols = self.acc_cols(col0)
        A[:, cols.start : cols.start + 3] = np.eye(3)
        A[:, cols.start + 3 : cols.stop] = -_skew(r)
        return A, np.cross(w, np.cross(w, r))

    def point_velocity(self, p: np.ndarray) -> np.ndarray:
        """The measured velocity of the object's material point at ``p``."""
        return self.vel + np.cross(self.omega, p - self.com)

    def carry(self, p_ref: np.ndarray) -> np.ndarray:
        """A point given relative to the reference object pose, carried to the measured one:
        ``c + R R_ref^T (p_ref - c_ref)``."""
        mo, t = self.held.motion, self.held.t
        return self.com + self.rot @ mo.rot[t].T @ (p_ref - mo.com[t])

    def hand_goal(
        self, p_ref: np.ndarray, v_ref: np.ndarray, press: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(goal, velocity)`` of a holding hand whose reference point is ``p_ref`` (velocity ``v_ref``): the point
        carried to the measured object pose (:meth:`carry`), plus ``press`` (the force loop's push along the inward
        normal, None: not in contact); the velocity of the object's material point there plus the reference's own
        motion relative to its object."""
        mo, t = self.held.motion, self.held.t
        goal = self.carry(p_ref) + (0.0 if press is None else press)
        rel = v_ref - mo.com_vel[t] - np.cross(mo.omega[t], p_ref - mo.com[t])
        return goal, self.point_velocity(goal) + self.rot @ mo.rot[t].T @ rel

    def normal_force_error(self, x: np.ndarray, col0: int) -> np.ndarray:
        """(2,) per hand, the QP's normal force of this step ``x`` (the block from column ``col0``) less the normal
        force MuJoCo delivered, summed over the hand's contacts (0 for a hand not in contact)."""
        err = np.zeros(2)
        for j, gp in enumerate(self.grips):
            err[gp.k] += float((x[col0 + 3 * j : col0 + 3 * j + 3] - gp.measured) @ gp.normal)
        return err

    def rows(self, col0: int, n: int, g: LoopGains) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(A, b, G, h)``: Newton-Euler and kinetic-friction equalities, friction and normal-force bounds."""
        A, b, G, h = [], [], [], []
        ne = np.zeros((6, n))
        cols = self.acc_cols(col0)
        ne[:3, cols.start : cols.start + 3] = self.mass * np.eye(3)
        ne[3:, cols.start + 3 : cols.stop] = self.inertia
        points = [g.point for g in self.grips] + self.support
        for j, p in enumerate(points):
            c = col0 + 3 * j
            ne[:3, c : c + 3] = -np.eye(3)
            ne[3:, c : c + 3] = -_skew(p - self.com)
        A.append(ne)
        b.append(
            np.r_[
                self.mass * GRAVITY + self.other[:3], self.other[3:] - np.cross(self.omega, self.inertia @ self.omega)
            ]
        )
        margin = g.friction_margin if self.held.squeezed else 1.0
        Gf, hf = friction_rows([contact_frame(gp.normal) for gp in self.grips], self.held.mu_hand / margin, col0, n)
        G, h = G + Gf, h + hf
        for j, gp in enumerate(self.grips):  # each contact presses at most max_normal
            most = np.zeros((1, n))
            most[0, col0 + 3 * j : col0 + 3 * j + 3] = gp.normal
            G.append(most)
            h.append(np.array([g.max_normal]))
        for hc in self.hands if self.held.squeezed else ():  # squeezing hands press at least min_normal each
            least = np.zeros((1, n))
            for j in hc.grips:
                least[0, col0 + 3 * j : col0 + 3 * j + 3] = -self.grips[j].normal
            G.append(least)
            h.append(np.array([-g.min_normal]))
        col_s = col0 + 3 * len(self.grips)
        if self.sliding is None:  # sticking: the support's friction pyramids
            Gs, hs = friction_rows([UP_FRAME] * len(self.support), self.held.mu_support, col_s, n)
            G, h = G + Gs, h + hs
        else:  # sliding: kinetic friction against the motion, f_t = -mu_s f_n u, f_n >= 0
            for i in range(len(self.support)):
                c = col_s + 3 * i
                eq = np.zeros((2, n))
                eq[0, c], eq[1, c + 1] = 1.0, 1.0
                eq[:, c + 2] = self.held.mu_support * self.sliding[:2]
                A.append(eq)
                b.append(np.zeros(2))
                nonneg = np.zeros((1, n))
                nonneg[0, c + 2] = -1.0
                G.append(nonneg)
                h.append(np.zeros(1))
        G.append(np.zeros((0, n)))
        h.append(np.zeros(0))
        return np.vstack(A), np.concatenate(b), np.vstack(G), np.concatenate(h)

    def tasks(self, col0: int, n: int, g: LoopGains) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """``[(A, b, w)]`` cost rows ``w ||A x - b||^2``: the object's PD task and the support's stillness."""
        mo, t = self.held.motion, self.held.t
        cols = self.acc_cols(col0)
        lin, ang = np.zeros((3, n)), np.zeros((3, n))
        lin[:, cols.start : cols.start + 3] = np.eye(3)
        ang[:, cols.start + 3 : cols.stop] = np.eye(3)
        err_r = orientation_error(mo.rot[t], self.rot)
        out = [
            (
                lin,
                mo.com_acc[t] + g.kp * (mo.com[t] - self.com) + g.kd * (mo.com_vel[t] - self.vel),
                np.full(3, g.w_object),
            ),
            (ang, mo.alpha[t] + g.kp_rot * err_r + g.kd_rot * (mo.omega[t] - self.omega), np.full(3, g.w_object_rot)),
        ]
        for p in self.support:
            Ap, bp = self.point_rows(p, col0, n)
            keep = Ap[2:] if self.sliding is not None else Ap  # sliding: only the normal stays
            out.append((keep, -(bp[2:] if self.sliding is not None else bp), np.full(len(keep), g.w_support)))
        return out
