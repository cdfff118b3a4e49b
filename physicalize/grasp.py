"""Holding objects by contact alone: a per-frame grasp schedule for the whole-body controller.

The object is a free body moved only by contact, so a hand holds it by pressing on it and by the
friction that pressure allows. From the clip's hand-object contact labels and the reference object
track this module plans, per control frame ``t`` and hand ``k``:

* **which hand holds which object.** A hand *holds* object ``o`` on frames where its contact label
  is set (runs shorter than :attr:`GraspConfig.min_run` dropped) and ``o`` is the free object nearest
  it (within :attr:`GraspConfig.max_gap`). Both hands on ``o`` facing each other across it (inward
  normals ``n_l . n_r <= -``:attr:`GraspConfig.min_opposition`) *squeeze* it; otherwise they press on it
  from one side (a push, a lift from below). One hand alone holds only an object the reference slides
  more than :attr:`GraspConfig.push_travel` without lifting it (a one-hand push).
* **where the hand goes: on the object's track.** At the run's anchor frame ``t_0`` (the first
  ``ramp_frames`` frames, least surface gap) MuJoCo's ``mj_geomDistance`` gives the hand surface's signed
  distance ``d_k`` to the object and its inward normal ``n_k``; the hand point ``c_k`` (its contact geoms'
  centre, a fixed point of the hand body) is fixed in the object frame, ``c_k^o = X_o(t_0)^-1 c_k``,
  and follows the *reference object pose*: ``c*_k(t) = (1 - s) c_k(t) + s (X_o(t) c_k^o + (d_k + delta) R_o(t) n_k^o)``
  (the retargeted hands drift off the object: omomo's were 15 cm below the box after the lift). The
  surface is driven ``delta`` (:attr:`GraspConfig.depth`) into the object; ``s(t)`` ramps 0 -> 1 over
  :attr:`GraspConfig.ramp_frames` at each end of a hold. For a squeeze the two normals are made exactly
  opposite, ``n = (n_l - n_r)/|n_l - n_r|``, and both anchors are moved onto one line along ``n`` through
  the point :attr:`GraspConfig.grip_above` over the object's centre of mass: point contacts resist no
  torque about the line between them, so offset anchors make the squeezes a couple that spins the object
  and a grip axis beside the centre of mass lets it swing. The feasible reference's IK re-solves the arms
  onto these targets (``attached``; :func:`physicalize.problem.tracking_problem`). A hand pushing an object along
  its support from a face whose normal cannot give the push is moved onto one that can, and a free hand near a lone
  push that one hand cannot give joins it (:mod:`physicalize.push_faces`). Squeezing hands also
  track their reference orientation (:attr:`GraspConfig.w_hold_rot`). Velocity and acceleration
  targets are the finite differences of ``c*``; the hand task weight is :attr:`GraspConfig.w_hold` while
  holding.
* **hands kept off what they do not touch.** A hand that is not labelled in contact (and not within
  :attr:`GraspConfig.approach_frames` of a labelled contact) whose reference surface comes closer than
  :attr:`GraspConfig.clearance` to an object gets its target moved out along the normal to that
  clearance, weight :attr:`GraspConfig.w_clear` (SitStand: the wrists lifted the chair 20 cm).
* **the force the hands must apply** (:mod:`physicalize.grasp_force`): the object's inertia, its weight once
  lifted and its sliding friction on its support, shared equally by the holding hands, each pressing its share
  into the object far enough for friction to carry the rest (squeezing) or pushing it from one side; where an
  equal share leaves a hand's friction cone while two hands push it along its support, they share it within their
  cones and so that their moment about the vertical through its centre of mass turns it as its reference turns (a
  hand may press it into its support); ramped in by ``s(t)``; ``friction_ok`` records whether the plan is within
  the hands' friction cones.

The controller (:class:`physicalize.wbc.WholeBodyController`) either puts the held object in its QP
(:mod:`physicalize.object_loop`: the hand targets carried onto the measured object pose, the forces its own
variables) or, in the open loop, adds ``-J_k^T f_k`` (the object's planned reaction at the hand point) to the
measured external generalized force ``tau_ext`` after removing the measured contact forces of the held object
on that whole forearm (:data:`physicalize.wbc.GRIP_LINKS`), whose one-step-old compensation would otherwise act
as an integrator on the squeeze: a blocked hand is pushed by the last contact force plus ``M qdd*`` more at every
step (measured: the box was dropped; the wrist capsules, compensated, pressed 30 N on its top edge and turned
it). Contacts of other links stay measured. The schedule gives the controller the held object's reference motion
(:class:`~physicalize.object_motion.ObjectMotion`) and both frictions (:class:`~physicalize.object_loop.HeldObject`).
Holding also needs the scene's elliptic friction cones with ``impratio`` 10 (:mod:`pipeline.scene`): with pyramidal
cones and ``impratio`` 1 a squeezed box crept down 2-3 cm/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from physicalize.grasp_config import GraspConfig
from physicalize.grasp_force import (
    ObjectLoad,
    floor_friction,
    hand_force,
    hand_friction,
    inertia_zz,
    press_allocation,
)
from physicalize.hand_reach import HandReach, ObjectTracks, hand_offsets, hand_reach
from physicalize.object_loop import HeldObject
from physicalize.object_motion import ObjectMotion
from physicalize.push_faces import PushFaces, pushed
from physicalize.target import Target
from pipeline.foot_contact import keep_runs, label_runs, runs, widen_runs
from pipeline.robot import HAND_BODIES
from pipeline.rotations import quat_mat
from pipeline.scene import Scene, hand_geoms


@dataclass
class GraspSchedule:
    """Per-frame hand targets and forces (``T`` frames, hands ordered left, right)."""

    offset: np.ndarray  # (2, 3) tracked hand point in its hand body frame
    point: np.ndarray  # (T, 2, 3) target of that point (world)
    vel: np.ndarray  # (T, 2, 3)
    acc: np.ndarray  # (T, 2, 3)
    weight: np.ndarray  # (T, 2) hand task weight
    force: np.ndarray  # (T, 2, 3) force each hand applies to the object (world)
    normal: np.ndarray  # (T, 2, 3) inward surface normal at the hand (0 when not grasping)
    grasped: np.ndarray  # (T, 2) bool
    body: np.ndarray  # (T, 2) int: body id of the grasped object, -1 none
    obj: np.ndarray  # (T,) int: index of the grasped object in the object list, -1 none
    # (T,) bool: the planned forces are within the hands' friction cones (True when not grasping)
    friction_ok: np.ndarray
    rot: np.ndarray  # (T, 2, 3, 3) reference hand orientations
    rot_weight: np.ndarray  # (T, 2) hand orientation task weight (0 when not grasping)
    mu: float
    # (T, 2, 3) the tracked hand point without the squeeze (on the object's track / kept off it)
    attached: np.ndarray | None = None
    # (T, 2) bool: the hand's target is moved off an object it does not touch in the reference
    clear: np.ndarray | None = None
    motions: dict[int, ObjectMotion] | None = None  # index of each held object -> its reference motion
    support_mu: dict[int, float] | None = None  # index of each held object -> its object-support friction
    squeezed: np.ndarray | None = None  # (T,) bool: both hands squeeze the held object between them

    def hand_body_targets(self) -> np.ndarray:
        """(T, 2, 3) hand body origins that put the tracked points on :attr:`attached` at the reference hand
        orientations."""
        return self.attached - np.einsum("tkij,kj->tki", self.rot, self.offset)

    def fill(self, target: Target, t: int) -> Target:
        """Set ``target``'s hand fields to frame ``t`` of the schedule (in place; returned)."""
        target.hand_pos, target.hand_vel, target.hand_acc = self.point[t], self.vel[t], self.acc[t]
        target.hand_offset, target.hand_weight, target.hand_force = self.offset, self.weight[t], self.force[t]
        target.hand_rot, target.hand_rot_weight = self.rot[t], self.rot_weight[t]
        i = int(self.obj[t])
        if i >= 0 and self.motions is not None:
            squeezed = self.squeezed is not None and bool(self.squeezed[t])
            target.held = HeldObject(
                int(self.body[t].max()), self.body[t] >= 0, self.motions[i], t, self.mu, self.support_mu[i], squeezed
            )
        return target


@dataclass
class _Holds:
    """Which hand holds which object: ``key`` (T, 2) the object index, -1 none; ``opposed`` (T,) both
    hands squeeze one object between them."""

    key: np.ndarray
    opposed: np.ndarray

    @property
    def held(self) -> np.ndarray:
        return self.key >= 0


def _ramp(mask: np.ndarray, n: int) -> np.ndarray:
    """Per frame in [0, 1]: 0 off the mask, rising/falling linearly over ``n`` frames at each run end
    inside the clip (a grasp the clip starts or ends with is held there at full strength)."""
    s = np.zeros(len(mask))
    big = len(mask) + n
    for a, b in runs(mask):
        k = np.arange(b - a)
        up = k + 1 if a > 0 else np.full(b - a, big)
        down = b - a - k if b < len(mask) else np.full(b - a, big)
        s[a:b] = np.minimum(1.0, np.minimum(up, down) / max(n, 1))
    return s


def grasp_schedule(
    scene: Scene,
    ref,
    contact_links: tuple[str, ...],
    contacts: np.ndarray | None,
    objects: dict[str, np.ndarray],
    cfg: GraspConfig = GraspConfig(),
) -> GraspSchedule | None:
    """The schedule for reference ``ref`` (:class:`physicalize.reference.Reference`, ``T`` frames) from
    the clip's contact labels ``contacts`` (T, len(contact_links)) and the reference object tracks
    ``objects`` (name -> (T, 7) pose); ``None`` when no frame holds an object and no hand needs
    keeping off one (the reference is left as it is)."""
    if not scene.object_qpos_adr:
        return None
    m, T = scene.model, ref.frames
    labels = hand_labels(contact_links, contacts, T, cfg)
    objs = ObjectTracks.of(scene, objects)
    near = hand_reach(scene, ref, objs, max(cfg.max_gap, cfg.clearance))
    holds = _holds(labels, near, objs, cfg)
    mu = _hold_friction(m, holds, objs)
    faces = PushFaces.of(m, objs, holds.key, holds.opposed, ref.fps, mu / cfg.safety, cfg)
    labels = faces.recruit(near.dist, cfg.max_gap, labels)  # a free hand near a lone push it cannot give joins it
    held = holds.held
    s = np.stack([_ramp(held[:, k], cfg.ramp_frames) for k in range(2)], axis=1)
    point, normal, gap = _on_object_tracks(m, near, holds, objs, s, cfg, faces)
    attached = point.copy()
    point += (s * (gap + cfg.depth))[..., None] * normal
    weight = cfg.w_free + s * (cfg.w_hold - cfg.w_free)
    clear = _keep_off(labels, near, point, attached, cfg)
    weight = np.where(clear, max(cfg.w_clear, cfg.w_free), weight)
    if not held.any() and not clear.any():
        return None
    dt = 1.0 / ref.fps
    vel = np.gradient(point, dt, axis=0) if T > 1 else np.zeros_like(point)
    acc = np.gradient(vel, dt, axis=0) if T > 2 else np.zeros_like(point)
    indices = sorted(set(holds.key[held].tolist()))
    motions = {i: ObjectMotion.of(objs.pose(i)[:T], m.body_ipos[objs.bodies[i]], ref.fps) for i in indices}
    force, friction_ok = _forces(m, holds, objs, motions, (attached, normal), s, mu, ref.fps, cfg)
    body = _held_bodies(holds, objs, T)
    return GraspSchedule(
        hand_offsets(m),
        point,
        vel,
        acc,
        weight,
        force,
        normal,
        held,
        body,
        np.where(held[:, 0], holds.key[:, 0], holds.key[:, 1]),
        friction_ok,
        near.rot,
        s * cfg.w_hold_rot * holds.opposed[:, None],
        float(mu) if np.isfinite(mu) else 0.0,
        attached,
        clear,
        motions,
        {i: floor_friction(m, objs.geoms[i]) for i in indices},
        holds.opposed.copy(),
    )


def hand_labels(contact_links: tuple[str, ...], contacts: np.ndarray | None, T: int, cfg: GraspConfig) -> np.ndarray:
    """(T, 2) bool: the clip labels each hand in contact (runs and gaps shorter than ``min_run`` dropped;
    all False without hand labels)."""
    links = list(contact_links)
    if contacts is None or not all(h in links for h in HAND_BODIES):
        return np.zeros((T, 2), bool)
    return np.stack(
        [
            keep_runs(
                keep_runs(np.asarray(contacts[:T, links.index(h)], bool), cfg.min_run, True),
                cfg.min_run,
                False,
            )
            for h in HAND_BODIES
        ],
        axis=1,
    )


def _holds(labels: np.ndarray, near: HandReach, objs: ObjectTracks, cfg: GraspConfig) -> _Holds:
    """A labelled hand within ``max_gap`` of its nearest object holds it (runs shorter than ``min_run``
    dropped); both hands on one object facing each other across it squeeze it; one hand alone holds only an
    object the reference pushes along its support (:func:`_pushed`). While the reference carries an object off its
    support, a hand within ``max_gap`` of the object the other (labelled) hand holds holds it too: no G1 hand lifts
    anything alone, and a human's contact labels flicker from hand to hand (sub2_woodchair_000: the chair raised
    overhead with both hands 1-8 cm from it, labelled one hand at a time, was never held and fell)."""
    near_held = labels & (near.dist < cfg.max_gap)
    partner = near_held[:, ::-1] & (near.dist < cfg.max_gap) & (near.obj == near.obj[:, ::-1])
    lifted = [objs.pose(i)[:, 2] - objs.pose(i)[:, 2].min() > cfg.lift_blend for i in range(len(objs.names))]
    carried = np.array([i >= 0 and bool(lifted[i][t]) for t, i in enumerate(near.obj.max(axis=1).tolist())])
    held = near_held | (partner & carried[:, None])
    both = held.all(axis=1) & (near.obj[:, 0] == near.obj[:, 1])
    opposed = both & (np.einsum("ti,ti->t", near.normal[:, 0], near.normal[:, 1]) <= -cfg.min_opposition)
    key = np.where(held, near.obj, -1)
    key[held.all(axis=1) & ~both] = -1  # both hands labelled on different objects: left to the reference
    for k in range(2):
        key[:, k] = np.where(keep_runs(key[:, k] >= 0, cfg.min_run, True), key[:, k], -1)
    for k in range(2):  # one hand alone only pushes an object along the floor
        alone = np.where((key[:, k] >= 0) & (key[:, 1 - k] != key[:, k]), key[:, k], -1)
        for a, b, i in label_runs(alone):
            if not pushed(objs.pose(i)[a:b], cfg.push_travel, cfg.lift_blend):
                key[a:b, k] = -1
    opposed &= (key >= 0).all(axis=1)
    return _Holds(key, opposed)


def _on_object_tracks(
    m: mujoco.MjModel,
    near: HandReach,
    holds: _Holds,
    objs: ObjectTracks,
    s: np.ndarray,
    cfg: GraspConfig,
    faces: PushFaces,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(point, normal, gap)`` (T, 2, 3), (T, 2, 3), (T, 2): the hand points blended by ``s`` onto their
    anchors fixed in the held object's frame (moved with its reference pose; a pushing hand's moved onto the face
    that can push, :mod:`physicalize.push_faces`), the inward normals (exactly opposite while squeezing) and the
    anchor frames' surface gaps; the reference hand points elsewhere."""
    T = len(s)
    point, normal, gap = near.point.copy(), np.zeros((T, 2, 3)), np.zeros((T, 2))
    for k in range(2):
        for a, b, i in label_runs(holds.key[:, k]):
            pose = objs.pose(i)
            t0, c_o, n_o = _anchor(m, near, holds.opposed, objs.bodies[i], pose, k, a, b, cfg)
            c_o, n_o = faces(i, k, a, b, c_o, n_o)
            g0 = near.dist[t0, k] if np.isfinite(near.dist[t0, k]) else 0.0  # a recruited hand: placed at a stand-off
            for t in range(a, b):
                R = quat_mat(pose[t, 3:7])
                normal[t, k] = R @ n_o
                gap[t, k] = g0
                point[t, k] = (1 - s[t, k]) * near.point[t, k] + s[t, k] * (pose[t, :3] + R @ c_o)
    for t in np.flatnonzero(holds.opposed):  # squeezes that cancel: exactly opposite normals
        n = normal[t, 0] - normal[t, 1]
        n /= max(np.linalg.norm(n), 1e-9)
        normal[t] = (n, -n)
    return point, normal, gap


def _anchor(
    m: mujoco.MjModel,
    near: HandReach,
    opposed: np.ndarray,
    body: int,
    pose: np.ndarray,
    k: int,
    a: int,
    b: int,
    cfg: GraspConfig,
) -> tuple[int, np.ndarray, np.ndarray]:
    """``(t_0, c_k^o, n_k^o)`` of hand ``k``'s hold ``[a, b)`` of the object ``body`` (reference track
    ``pose``): the anchor frame (least surface gap in the first ``ramp_frames``; one frame for both hands of
    a two-hand grip), and the hand point and inward normal there in the object's frame. A two-hand grip's
    points go onto one line along the grip normal through the point ``grip_above`` over the object's centre
    of mass (else the squeezes make a couple that spins the object)."""
    win = np.arange(a, min(b, a + cfg.ramp_frames))
    both_in = win[opposed[win]]
    if both_in.size:  # a two-hand grip: one anchor frame for both hands, the grip axis moved over the centre of mass
        t0 = int(both_in[np.argmin(np.abs(near.dist[both_in]).sum(axis=1))])
    else:
        t0 = int(win[np.argmin(np.abs(near.dist[win, k]))])
    R0 = quat_mat(pose[t0, 3:7])
    c0 = near.point[t0, k].copy()
    if both_in.size:
        n = near.normal[t0, 0] - near.normal[t0, 1]
        n /= max(np.linalg.norm(n), 1e-9)
        axis = near.point[t0].mean(axis=0)
        if cfg.grip_above is not None:
            axis = pose[t0, :3] + R0 @ m.body_ipos[body] + [0.0, 0.0, cfg.grip_above]
        c0 = axis + ((c0 - axis) @ n) * n
    return t0, R0.T @ (c0 - pose[t0, :3]), R0.T @ near.normal[t0, k]


def _keep_off(
    labels: np.ndarray, near: HandReach, point: np.ndarray, attached: np.ndarray, cfg: GraspConfig
) -> np.ndarray:
    """(T, 2) bool: the hands kept off objects they do not touch in the reference (not labelled within
    ``approach_frames``, surface closer than ``clearance``), whose ``point`` and ``attached`` targets are moved
    out along the normal to the clearance (in place)."""
    near_run = np.stack([widen_runs(labels[:, k], cfg.approach_frames) for k in range(2)], axis=1)
    clear = ~near_run & (near.dist < cfg.clearance)
    push_out = np.where(clear, cfg.clearance - near.dist, 0.0)
    point -= push_out[..., None] * near.normal
    attached -= push_out[..., None] * near.normal
    return clear


def _hold_friction(m: mujoco.MjModel, holds: _Holds, objs: ObjectTracks) -> float:
    """The least hand-object friction over the objects held (inf: none held; raises for a frictionless pair)."""
    hgeoms = hand_geoms(m)
    return min(
        [np.inf]
        + [hand_friction(m, hgeoms, objs.geoms[i], objs.names[i]) for i in sorted(set(holds.key[holds.held].tolist()))]
    )


def _forces(
    m: mujoco.MjModel,
    holds: _Holds,
    objs: ObjectTracks,
    motions: dict[int, ObjectMotion],
    contact: tuple[np.ndarray, np.ndarray],
    s: np.ndarray,
    mu: float,
    fps: float,
    cfg: GraspConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """``(force (T, 2, 3), friction_ok (T,))``: the force each holding hand applies to its object, ramped by ``s``,
    and whether every hand's is within friction. The object needs ``F`` (:mod:`physicalize.grasp_force`); the
    holding hands take ``F / n_hands`` each (:func:`~physicalize.grasp_force.hand_force`). Where that leaves a cone
    while two hands push the object along its support from one side
    (:meth:`~physicalize.grasp_force.ObjectLoad.slides`; a hand on the lid, one on a side) they share ``F`` within
    their cones instead, turning it as its reference turns (``tau_z = I_zz alpha_z`` about its centre of mass) and
    pressing it into its support where that helps (:func:`~physicalize.grasp_force.press_allocation`). Only there:
    allocating wherever two hands push moved the default Push's forces off its equal split (9.6 / 27.3 N for
    18.4 / 18.4) and its teacher's root accuracy from > 0.9 to 0.83; on lifted frames it put a table's weight on
    one wrist (sub2_largetable_003: 2.73x the wrist pitch's effort limit, rejected `over torque`).
    ``contact``: the hand points on the object (T, 2, 3) and their inward normals (T, 2, 3)."""
    key, held, opposed = holds.key, holds.held, holds.opposed
    point, normal = contact
    T = len(key)
    force, friction_ok = np.zeros((T, 2, 3)), np.ones(T, bool)
    for a, b, _ in label_runs(np.where(held.any(axis=1), np.where(held[:, 0], key[:, 0], key[:, 1]), -1)):
        i = int(key[a, 0] if held[a, 0] else key[a, 1])
        load = ObjectLoad.of(m, objs.bodies[i], objs.geoms[i], objs.pose(i)[:T, :3], a, fps, cfg)
        motion, inertia = motions[i], inertia_zz(m, objs.bodies[i], motions[i].rot)
        for t in range(a, b):
            hands = [k for k in range(2) if key[t, k] == i]
            F = load.force(t, opposed[t], cfg)
            split = [hand_force(F / len(hands), normal[t, k], mu, opposed[t], cfg) for k in hands]
            if len(hands) == 2 and not opposed[t] and load.slides(t, cfg) and not all(ok for _, ok in split):
                arms, support = point[t] - motion.com[t], load.support(t, cfg)
                f, ok = press_allocation(F, inertia[t] * motion.alpha[t, 2], arms, normal[t], mu, cfg, support)
                split = list(zip(f, [ok, ok]))
            for k, (f_k, ok) in zip(hands, split):
                force[t, k] = s[t, k] * f_k
                friction_ok[t] &= ok
    return force, friction_ok


def _held_bodies(holds: _Holds, objs: ObjectTracks, T: int) -> np.ndarray:
    """(T, 2) the body id of the object each hand holds (-1 none)."""
    body = np.full((T, 2), -1)
    for k in range(2):
        for a, b, i in label_runs(holds.key[:, k]):
            body[a:b, k] = objs.bodies[i]
    return body
