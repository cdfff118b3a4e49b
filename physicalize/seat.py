"""Sitting on an object: where a seat supports the reference, and the seat contacts the whole-body QP holds.

**Seat support of the reference** (:func:`seat_support`). On frames where the clip labels the pelvis on an
object (runs shorter than :attr:`SeatConfig.min_run` dropped, then dilated by :attr:`SeatConfig.dilate`
frames: the body leaves or reaches the seat around the label), each sitting link (:data:`SEAT_LINKS`) of the
kinematic reference within :attr:`SeatConfig.reach` of an object's upward-facing surface supports there: its
nearest point is a seat support point. The ZMP plan's support region is the convex hull of the stance feet
and these points (:func:`physicalize.plan.support_polygon`): a human sits with the centre of mass behind the
heels, where only the seat carries it. The G1 sits on the tops of its thighs (the hip links), in front of its
pelvis: the retargeted SitStand put the CoM 4 cm behind them, so the robot rolled back onto its pelvis, the
feet left the floor and it could not stand up again. The plan keeps the CoM over the hull instead.

**Support contacts** (:func:`support_points`). While seated (``Target.seated``: the reference has seat points),
every robot body other than the feet and the grip links (forearms, hands) that touches an object from above --
contact normal within 45 degrees of the vertical -- is one contact point of the QP: the mean position of that
body's contacts, with a 3-D force ``f`` in the friction pyramid about the mean normal ``n``
(``|f.t_i| <= mu/sqrt 2 f.n``, ``f.n >= 0``), and the point held like a stance foot, softly
(``J_p qdd + Jdot_p qd = -k_v v`` with weight ``w_seat``). Those measured contacts leave the QP's
``tau_ext``: the QP chooses the seat's force instead of taking it as given (taken as given, the robot reclined
48 degrees onto the backrest). Side contacts (a backrest) stay measured external forces.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from physicalize.reference import Reference
from pipeline.contacts import ContactSets, robot_contacts
from pipeline.foot_contact import keep_runs, widen_runs
from pipeline.robot import NQ_ROBOT, NV_ROBOT
from pipeline.scene import nearest_geom_pair

SUPPORT_NORMAL_Z = np.cos(np.pi / 4)  # a contact whose normal is this close to vertical supports from below
SEAT_LINKS = (
    "pelvis",
    "left_hip_pitch_link",
    "left_hip_roll_link",
    "left_hip_yaw_link",
    "right_hip_pitch_link",
    "right_hip_roll_link",
    "right_hip_yaw_link",
)
MAX_SEAT_POINTS = len(SEAT_LINKS)


@dataclass(frozen=True)
class SeatConfig:
    """Seat support parameters."""

    min_run: int = 3  # frames: shorter pelvis-label runs (and gaps) are dropped
    # frames the labelled runs are widened by at each end (10: SitStand fell at 7.2 s, its hips reach the seat 0.7 s
    # before the label)
    dilate: int = 40
    reach: float = 0.02  # m: a sitting link this close to an object's upward-facing surface sits on it


@dataclass(frozen=True)
class SupportPoint:
    """One seat contact point of the QP: ``body``, world ``point``, ``frame`` (3, 3) rows (normal into the
    robot, two tangents), and ``tau`` (35,): the measured generalized force of the contacts it replaces."""

    body: int
    point: np.ndarray
    frame: np.ndarray
    tau: np.ndarray


def seat_support(
    model: mujoco.MjModel,
    ref: Reference,
    contact_links: tuple[str, ...],
    contacts: np.ndarray | None,
    objects_qpos: np.ndarray | None,
    cfg: SeatConfig = SeatConfig(),
) -> np.ndarray | None:
    """(T, :data:`MAX_SEAT_POINTS`, 3) seat support points of the kinematic reference ``ref`` (NaN rows where
    a link does not sit), see the module docstring; ``None`` when the clip never sits. ``objects_qpos``
    (T, nq - 36) places the scene's free objects per frame (None: as in the model)."""
    if contacts is None or "pelvis" not in contact_links:
        return None
    T = ref.frames
    label = np.asarray(contacts[:T, list(contact_links).index("pelvis")], bool)
    seated = keep_runs(keep_runs(label, cfg.min_run, True), cfg.min_run, False)
    seated = widen_runs(seated, cfg.dilate)
    if not seated.any():
        return None
    links = [
        [g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body(name).id and model.geom_contype[g]]
        for name in SEAT_LINKS
    ]
    robot = model.body("pelvis").id
    objects = [
        g
        for g in range(model.ngeom)
        if model.geom_contype[g] and model.geom_bodyid[g] and model.body_rootid[model.geom_bodyid[g]] != robot
    ]
    d = mujoco.MjData(model)
    out = np.full((T, MAX_SEAT_POINTS, 3), np.nan)
    fromto = np.zeros(6)
    for t in np.flatnonzero(seated):
        d.qpos[:NQ_ROBOT] = ref.qpos[t]
        if objects_qpos is not None:
            d.qpos[NQ_ROBOT:] = objects_qpos[t]
        mujoco.mj_kinematics(model, d)
        for i, geoms in enumerate(links):
            dist, _, _ = nearest_geom_pair(model, d, geoms, objects, cfg.reach, fromto)
            v = (fromto[:3] - fromto[3:]) * (1.0 if dist >= 0 else -1.0)  # from the object's surface to the link
            if dist < cfg.reach and (
                np.linalg.norm(v) < 1e-4 or v[2] >= SUPPORT_NORMAL_Z * np.linalg.norm(v)
            ):  # on an upward-facing surface
                out[t, i] = fromto[:3]
    return out if np.isfinite(out).any() else None


def support_points(robot: ContactSets, d: mujoco.MjData, exclude: set[int]) -> list[SupportPoint]:
    """The seat contact points (see the module docstring) of the current state, one per robot body that
    an object supports from below; robot geoms in ``exclude`` (the feet, the grip links) are left out."""
    m = robot.model
    acc: dict[int, list] = {}
    for c in robot_contacts(m, d, robot.robot_geoms):
        if c.other == robot.floor or c.geom in exclude:
            continue
        n = c.normal  # the contact normal points from geom1 to geom2: here into the robot
        if n[2] < SUPPORT_NORMAL_Z:
            continue
        f = c.force()
        body = int(m.geom_bodyid[c.geom])
        jp = np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jp, None, c.pos, body)
        entry = acc.setdefault(body, [np.zeros(3), np.zeros(3), 0, np.zeros(jp.shape[1])])
        entry[0] += c.pos
        entry[1] += n
        entry[2] += 1
        entry[3] += jp.T @ f
    out = []
    for body, (p, n, k, tau) in acc.items():
        n = n / np.linalg.norm(n)
        t1 = np.cross(n, [0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.cross(n, [1.0, 0.0, 0.0])
        t1 /= np.linalg.norm(t1)
        out.append(SupportPoint(body, p / k, np.array([n, t1, np.cross(n, t1)]), tau[:NV_ROBOT]))
    return out
