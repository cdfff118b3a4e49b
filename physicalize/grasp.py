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
  onto these targets (``attached``; :func:`physicalize.problem.tracking_problem`). Squeezing hands also
  track their reference orientation (:attr:`GraspConfig.w_hold_rot`). Velocity and acceleration
  targets are the finite differences of ``c*``; the hand task weight is :attr:`GraspConfig.w_hold` while
  holding.
* **hands kept off what they do not touch.** A hand that is not labelled in contact (and not within
  :attr:`GraspConfig.approach_frames` of a labelled contact) whose reference surface comes closer than
  :attr:`GraspConfig.clearance` to an object gets its target moved out along the normal to that
  clearance, weight :attr:`GraspConfig.w_clear` (SitStand: the wrists lifted the chair 20 cm).
* **the force the hands must apply.** With the reference object velocity ``v_o`` and acceleration
  ``a_o`` (central differences of its track) and ``lambda(t) = clip((z_o(t) - z_o(t_0)) / lift_blend, 0, 1)``
  (0 while the object rests where the hold started, 1 once lifted), the hands must apply
  ``F = m [a_o,xy; lambda a_o,z] + lambda m g e_z + r mu_s m g min(1, |v_xy| / slide_speed) v_xy/|v_xy|``
  (its inertia, its weight once lifted, its sliding friction on its support for the share ``r`` of its
  weight that still rests there; ``mu_s``: the object-floor friction by MuJoCo's mixing rule); a one-side
  lift carries only :attr:`GraspConfig.side_lift` of the weight (the far side still rests, and drags:
  ``r = 1 - side_lift lambda``; between squeezing hands ``r = 1 - lambda``). Each holding hand takes
  ``F_k = F / n_hands``. Squeezing: the part along the surface, ``F_t,k = F_k - (F_k . n_k) n_k``, must come
  from friction, so ``N_k = clip(max(N_min, safety |F_t,k| / mu), 0, N_max)`` and ``f_k = s (N_k n_k + F_k)``.
  Pressing from one side there is no squeeze to cancel: ``N_k = max(F_k . n_k, safety |F_t,k| / mu, 0)``,
  ``f_k = s (F_k + (N_k - F_k . n_k) n_k)`` (exactly ``F_k`` for a push along the normal). ``|f_k|`` is capped
  at :attr:`GraspConfig.max_hand_force`; ``friction_ok`` records whether the plan is within friction: squeezing,
  ``mu N_k >= |F_t,k|`` under the caps; pressing from one side, the force needed itself in the cone,
  ``mu F_k . n_k >= |F_t,k|`` (a hand that only presses cannot pull: the InterMimic table, dragged towards the body).
  ``mu`` and ``condim`` of a
  hand-object contact follow MuJoCo's mixing rule (:func:`contact_friction`): the geom with the higher
  ``priority`` decides, else the larger friction and condim; ``condim 1`` (frictionless) cannot hold
  anything and raises.

The controller (:class:`physicalize.wbc.WholeBodyController`) adds ``-J_k^T f_k`` (the object's
reaction at the hand point) to the measured external generalized force ``tau_ext`` -- so the QP's
floating-base rows and torques carry the object's weight and inertia while the reference lifts it;
with :attr:`GraspConfig.replace_measured` it first removes the measured contact forces of the held
object on that whole forearm (:data:`physicalize.wbc.GRIP_LINKS`), whose one-step-old compensation
would otherwise act as an integrator on the squeeze: a blocked hand is pushed by the last contact
force plus ``M qdd*`` more at every step (measured: the box was dropped; the wrist capsules,
compensated, pressed 30 N on its top edge and turned it). Contacts of other links stay measured.
Optionally (:attr:`GraspConfig.w_hold_rot`) the grasping hands also track their reference
orientation. Holding also needs the scene's elliptic friction cones with ``impratio`` 10
(:mod:`pipeline.scene`): with pyramidal cones and ``impratio`` 1 a squeezed box crept down 2-3 cm/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from physicalize.target import Target
from pipeline.foot_contact import keep_runs, runs
from pipeline.robot import HAND_BODIES, NQ_ROBOT
from pipeline.rotations import quat_mat
from pipeline.scene import Scene, link_collision_geoms, nearest_geom_pair

GRAVITY = 9.81
# N: a planned force this far outside a friction cone still counts as inside (resting objects: numerical noise)
FRICTION_TOL_N = 0.5


@dataclass(frozen=True)
class GraspConfig:
    """Grasp planning parameters (lengths in m, forces in N)."""

    depth: float = 0.03  # target penetration of the hand surface into the object
    safety: float = 2.0  # normal force = safety * tangential load / mu
    min_normal_force: float = 10.0
    max_normal_force: float = 60.0
    min_run: int = 3  # frames: shorter contact-label runs are dropped
    ramp_frames: int = 10  # squeeze/force ramp at the start and end of a grasp
    lift_blend: float = 0.02  # object rise over which its weight moves onto the hands
    min_opposition: float = 0.3  # grasp only if n_l . n_r <= -min_opposition
    max_gap: float = 0.10  # a labelled hand farther than this from the object does not grasp
    w_hold: float = 100.0  # hand task weight while grasping
    w_free: float = 5.0  # hand task weight otherwise (the controller's default)
    # hand orientation task weight while squeezing an object between the hands (omomo box: 0 -> 20 kept it in the grip,
    # obj err 0.247 -> 0.066 m)
    w_hold_rot: float = 20.0
    replace_measured: bool = True
    slide_speed: float = 0.05  # m/s: a sliding object's floor friction is ramped in up to this reference speed
    push_travel: float = 0.10  # m: a one-hand contact holds only an object the reference slides this far (a push)
    max_hand_force: float = 120.0  # N: cap on the force one hand applies
    clearance: float = 0.05  # m: an unlabelled hand's surface is kept this far from objects
    # ... except this many frames before and after its labelled contacts (reaching, letting go)
    approach_frames: int = 25
    w_clear: float = 50.0
    # share of a lifted object's weight the hands carry when they hold it from one side (not squeezed between them)
    side_lift: float = 0.5
    grip_above: float | None = (
        # m: a two-hand grip's axis is moved onto the vertical through the object's centre of mass, this high above it
        # (None: where the reference hands are)  # hand task weight while it is kept off an object
        0.03
    )


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
    friction_ok: (
        np.ndarray
    )  # (T,) bool: the planned forces are within the hands' friction cones (True when not grasping)
    rot: np.ndarray  # (T, 2, 3, 3) reference hand orientations
    rot_weight: np.ndarray  # (T, 2) hand orientation task weight (0 when not grasping)
    mu: float
    replace_measured: bool = True
    # (T, 2, 3) the tracked hand point without the squeeze (on the object's track / kept off it)
    attached: np.ndarray | None = None
    hold_ref: np.ndarray | None = None  # (T, 2, 3) reference position of the object each hand holds (0 when none)
    # (T, 2) bool: the hand's target is moved off an object it does not touch in the reference
    clear: np.ndarray | None = None

    def hand_body_targets(self) -> np.ndarray:
        """(T, 2, 3) hand body origins that put the tracked points on :attr:`attached` at the reference hand
        orientations."""
        return self.attached - np.einsum("tkij,kj->tki", self.rot, self.offset)

    def fill(self, target: Target, t: int) -> Target:
        """Set ``target``'s hand fields to frame ``t`` of the schedule (in place; returned)."""
        target.hand_pos, target.hand_vel, target.hand_acc = self.point[t], self.vel[t], self.acc[t]
        target.hand_offset, target.hand_weight, target.hand_force = self.offset, self.weight[t], self.force[t]
        target.hand_object = self.body[t] if self.replace_measured else np.full(2, -1)
        target.hand_rot, target.hand_rot_weight = self.rot[t], self.rot_weight[t]
        if self.hold_ref is not None:
            target.hand_hold_body, target.hand_hold_ref = self.body[t], self.hold_ref[t]
        return target


def contact_friction(model: mujoco.MjModel, g1: int, g2: int) -> tuple[int, float]:
    """``(condim, mu)`` MuJoCo uses for a contact between geoms ``g1`` and ``g2``: those of the geom
    with the higher ``priority``; at equal priority the larger condim and the larger sliding friction."""
    p1, p2 = model.geom_priority[g1], model.geom_priority[g2]
    if p1 != p2:
        g = g1 if p1 > p2 else g2
        return int(model.geom_condim[g]), float(model.geom_friction[g, 0])
    return int(max(model.geom_condim[g1], model.geom_condim[g2])), float(
        max(model.geom_friction[g1, 0], model.geom_friction[g2, 0])
    )


def hand_geoms(model: mujoco.MjModel) -> list[list[int]]:
    """Collision geoms of each hand (left, right)."""
    return [link_collision_geoms(model, b) for b in HAND_BODIES]


def hand_offsets(model: mujoco.MjModel) -> np.ndarray:
    """(2, 3) each hand's tracked point in its body frame: the mean centre of its own collision geoms."""
    out = np.zeros((2, 3))
    for k, geoms in enumerate(hand_geoms(model)):
        own = [g for g in geoms if model.geom_bodyid[g] == model.body(HAND_BODIES[k]).id]
        if own:
            out[k] = model.geom_pos[own].mean(axis=0)
    return out


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


def normal_force(load: np.ndarray, n: np.ndarray, mu: float, cfg: GraspConfig) -> tuple[float, bool]:
    """``(N, ok)``: squeeze force for a hand carrying ``load`` (3,) through a contact of inward
    normal ``n`` and friction ``mu``; ``ok``: ``mu N >= |load_t|``."""
    tangential = float(np.linalg.norm(load - (load @ n) * n))
    N = float(np.clip(max(cfg.min_normal_force, cfg.safety * tangential / mu), 0.0, cfg.max_normal_force))
    return N, mu * N >= tangential - 1e-9


def press_force(load: np.ndarray, n: np.ndarray, mu: float, cfg: GraspConfig) -> tuple[np.ndarray, bool]:
    """``(f, ok)``: the force a hand pressing on an object from one side (inward normal ``n``, friction ``mu``)
    applies for its share ``load`` (3,) of the needed force: ``load`` plus the normal force that makes its
    tangential part at most ``mu / safety`` of the normal one, ``f = load + (N - load.n) n`` with
    ``N = max(load.n, safety |load_t| / mu, 0)``; ``ok``: ``load`` itself lies in the friction cone,
    ``mu load.n >= |load_t|`` (within :data:`FRICTION_TOL_N`): a hand that only presses cannot pull."""
    push = float(load @ n)
    tangential = float(np.linalg.norm(load - push * n))
    N = min(max(push, cfg.safety * tangential / mu, 0.0), cfg.max_hand_force)
    return load + (N - push) * n, mu * push >= tangential - FRICTION_TOL_N


def _label_runs(key: np.ndarray) -> list[tuple[int, int, int]]:
    """``(a, b, value)`` of the runs of equal values >= 0 in an int array."""
    out, a = [], 0
    for t in range(1, len(key) + 1):
        if t == len(key) or key[t] != key[a]:
            if key[a] >= 0:
                out.append((a, t, int(key[a])))
            a = t
    return out


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
    links = list(contact_links)
    if contacts is None or not all(h in links for h in HAND_BODIES):
        labels = np.zeros((ref.frames, 2), bool)
    else:
        labels = np.stack(
            [
                keep_runs(
                    keep_runs(np.asarray(contacts[: ref.frames, links.index(h)], bool), cfg.min_run, True),
                    cfg.min_run,
                    False,
                )
                for h in HAND_BODIES
            ],
            axis=1,
        )
    m, T, fps = scene.model, ref.frames, ref.fps
    names = list(scene.object_qpos_adr)
    obj_geoms = [
        [g for g in range(m.ngeom) if m.geom_contype[g] and m.geom_bodyid[g] == scene.object_body_id[n]] for n in names
    ]
    hgeoms = hand_geoms(m)
    hand_ids = [m.body(b).id for b in HAND_BODIES]
    offset = hand_offsets(m)
    d = mujoco.MjData(m)
    centre, rot = np.zeros((T, 2, 3)), np.zeros((T, 2, 3, 3))
    near_d, near_n, near_o = (
        np.full((T, 2), np.inf),
        np.zeros((T, 2, 3)),
        np.full((T, 2), -1),
    )  # nearest object per hand
    reach = max(cfg.max_gap, cfg.clearance)
    fromto = np.zeros(6)
    for t in range(T):
        d.qpos[:NQ_ROBOT] = ref.qpos[t]
        for n in names:
            adr = scene.object_qpos_adr[n]
            d.qpos[adr : adr + 7] = objects[n][t]
        mujoco.mj_kinematics(m, d)
        for k in range(2):
            rot[t, k] = d.xmat[hand_ids[k]].reshape(3, 3)
            centre[t, k] = d.xpos[hand_ids[k]] + rot[t, k] @ offset[k]
            for i, og in enumerate(obj_geoms):
                dist, _, _ = nearest_geom_pair(m, d, hgeoms[k], og, reach, fromto)
                if dist < min(reach, near_d[t, k]):
                    v = (fromto[3:] - fromto[:3]) * (1.0 if dist >= 0 else -1.0)
                    nv = np.linalg.norm(v)
                    near_d[t, k], near_o[t, k] = dist, i
                    near_n[t, k] = (
                        v / nv
                        if nv > 1e-6
                        else (d.xipos[scene.object_body_id[names[i]]] - centre[t, k])
                        / max(np.linalg.norm(d.xipos[scene.object_body_id[names[i]]] - centre[t, k]), 1e-9)
                    )
    # which hand holds which object, per frame
    held = labels & (near_d < cfg.max_gap)
    both = held.all(axis=1) & (near_o[:, 0] == near_o[:, 1])
    opposed = both & (np.einsum("ti,ti->t", near_n[:, 0], near_n[:, 1]) <= -cfg.min_opposition)
    key = np.where(held, near_o, -1)
    key[held.all(axis=1) & ~both] = -1  # both hands labelled on different objects: left to the reference
    for k in range(2):
        key[:, k] = np.where(keep_runs(key[:, k] >= 0, cfg.min_run, True), key[:, k], -1)
    for k in range(2):  # one hand alone only pushes an object along the floor
        alone = np.where((key[:, k] >= 0) & (key[:, 1 - k] != key[:, k]), key[:, k], -1)
        for a, b, i in _label_runs(alone):
            if not _pushed(objects[names[i]][a:b], cfg):
                key[a:b, k] = -1
    held = key >= 0
    opposed &= held.all(axis=1)
    s = np.stack([_ramp(held[:, k], cfg.ramp_frames) for k in range(2)], axis=1)
    # targets fixed to the object: the hand point and normal where the run starts, moved with the object's reference
    # pose
    point, normal, gap = centre.copy(), np.zeros((T, 2, 3)), np.zeros((T, 2))
    for k in range(2):
        for a, b, i in _label_runs(key[:, k]):
            pose = objects[names[i]]
            win = np.arange(a, min(b, a + cfg.ramp_frames))
            both_in = win[opposed[win]]
            if (
                both_in.size
            ):  # a two-hand grip: one anchor frame for both hands, the grip axis moved over the centre of mass
                t0 = int(both_in[np.argmin(np.abs(near_d[both_in]).sum(axis=1))])
            else:
                t0 = int(win[np.argmin(np.abs(near_d[win, k]))])
            R0 = quat_mat(pose[t0, 3:7])
            c0 = centre[t0, k].copy()
            # both hand points on one line along the grip normal (else the squeezes make a couple that spins the object)
            if both_in.size:
                n = near_n[t0, 0] - near_n[t0, 1]
                n /= max(np.linalg.norm(n), 1e-9)
                axis = centre[t0].mean(axis=0)
                if cfg.grip_above is not None:
                    axis = pose[t0, :3] + R0 @ m.body_ipos[scene.object_body_id[names[i]]] + [0.0, 0.0, cfg.grip_above]
                c0 = axis + ((c0 - axis) @ n) * n
            c_o, n_o = R0.T @ (c0 - pose[t0, :3]), R0.T @ near_n[t0, k]
            for t in range(a, b):
                R = quat_mat(pose[t, 3:7])
                normal[t, k] = R @ n_o
                gap[t, k] = near_d[t0, k]
                point[t, k] = (1 - s[t, k]) * centre[t, k] + s[t, k] * (pose[t, :3] + R @ c_o)
    for t in np.flatnonzero(opposed):  # squeezes that cancel: exactly opposite normals
        n = normal[t, 0] - normal[t, 1]
        n /= max(np.linalg.norm(n), 1e-9)
        normal[t] = (n, -n)
    attached = point.copy()
    point += (s * (gap + cfg.depth))[..., None] * normal
    # hands kept off objects they do not touch in the reference
    weight = cfg.w_free + s * (cfg.w_hold - cfg.w_free)
    near_run = np.stack([_dilate(labels[:, k], cfg.approach_frames) for k in range(2)], axis=1)
    clear = ~near_run & (near_d < cfg.clearance)
    push_out = np.where(clear, cfg.clearance - near_d, 0.0)
    point -= push_out[..., None] * near_n
    attached -= push_out[..., None] * near_n
    weight = np.where(clear, max(cfg.w_clear, cfg.w_free), weight)
    dt = 1.0 / fps
    vel = np.gradient(point, dt, axis=0) if T > 1 else np.zeros_like(point)
    acc = np.gradient(vel, dt, axis=0) if T > 2 else np.zeros_like(point)
    force = np.zeros((T, 2, 3))
    friction_ok = np.ones(T, bool)
    body = np.full((T, 2), -1)
    mu = np.inf
    for i in sorted(set(key[held].tolist())):
        name = names[i]
        bid = scene.object_body_id[name]
        for k in range(2):
            for hg in hgeoms[k]:
                for og in obj_geoms[i]:
                    condim, f = contact_friction(m, hg, og)
                    if condim < 3 or f <= 0:
                        raise ValueError(
                            f"hand geom {m.geom(hg).name!r} on {name!r}: condim {condim}, friction {f}: a frictionless "
                            "contact cannot hold"
                        )
                    mu = min(mu, f)
    hold_ref = np.zeros((T, 2, 3))
    for k in range(2):
        for a, b, i in _label_runs(key[:, k]):
            body[a:b, k] = scene.object_body_id[names[i]]
            hold_ref[a:b, k] = objects[names[i]][a:b, :3]
    for a, b, _ in _label_runs(np.where(held.any(axis=1), np.where(held[:, 0], key[:, 0], key[:, 1]), -1)):
        i = int(key[a, 0] if held[a, 0] else key[a, 1])
        name = names[i]
        bid = scene.object_body_id[name]
        mass = float(m.body_subtreemass[bid])
        floor_mu = _floor_friction(m, obj_geoms[i])
        pos = objects[name][:T, :3]
        v_o = np.gradient(pos, dt, axis=0) if T > 1 else np.zeros_like(pos)
        a_o = np.gradient(v_o, dt, axis=0) if T > 2 else np.zeros_like(pos)
        lam = np.clip((pos[:, 2] - pos[a, 2]) / cfg.lift_blend, 0.0, 1.0)
        for t in range(a, b):
            hands = [k for k in range(2) if key[t, k] == i]
            speed = float(np.linalg.norm(v_o[t, :2]))
            drag = np.zeros(3)
            if speed > 1e-6:  # sliding on its support: kinetic friction against the motion
                drag[:2] = floor_mu * mass * GRAVITY * min(1.0, speed / cfg.slide_speed) * v_o[t, :2] / speed
            rest = 1 - lam[t] if opposed[t] else 1 - cfg.side_lift * lam[t]  # share of its weight still on its support
            F = (
                mass * np.r_[a_o[t, :2], lam[t] * a_o[t, 2]]
                + lam[t] * mass * GRAVITY * np.array([0, 0, 1.0])
                + rest * drag
            )
            if not opposed[t]:  # lifted from one side only: the far side still rests on its support
                F[2] -= (1 - cfg.side_lift) * lam[t] * mass * (GRAVITY + a_o[t, 2])
            share = F / len(hands)
            for k in hands:
                if opposed[t]:
                    N, ok = normal_force(share, normal[t, k], mu, cfg)
                    f_k = N * normal[t, k] + share
                else:  # pushing from one side: no squeeze to cancel
                    f_k, ok = press_force(share, normal[t, k], mu, cfg)
                nf = np.linalg.norm(f_k)
                if nf > cfg.max_hand_force:
                    f_k *= cfg.max_hand_force / nf
                    ok = False
                force[t, k] = s[t, k] * f_k
                friction_ok[t] &= ok
    if not held.any() and not clear.any():
        return None
    return GraspSchedule(
        offset,
        point,
        vel,
        acc,
        weight,
        force,
        normal,
        held,
        body,
        np.where(held[:, 0], key[:, 0], key[:, 1]),
        friction_ok,
        rot,
        s * cfg.w_hold_rot * opposed[:, None],
        float(mu) if np.isfinite(mu) else 0.0,
        cfg.replace_measured,
        attached,
        hold_ref,
        clear,
    )


def _pushed(pose: np.ndarray, cfg: GraspConfig) -> bool:
    """The object slides along its support during these frames: it moves > ``push_travel`` horizontally and is not
    lifted."""
    travel = float(np.linalg.norm(pose[:, :2] - pose[0, :2], axis=1).max())
    return travel > cfg.push_travel and float(pose[:, 2].max() - pose[0, 2]) < cfg.lift_blend


def _dilate(mask: np.ndarray, n: int) -> np.ndarray:
    out = mask.copy()
    for a, b in runs(mask):
        out[max(0, a - n) : b + n] = True
    return out


def _floor_friction(model: mujoco.MjModel, geoms: list[int]) -> float:
    """Sliding friction of the object's geoms on the floor (MuJoCo's mixing rule)."""
    floor = model.geom("floor").id
    return max(contact_friction(model, g, floor)[1] for g in geoms) if geoms else 0.0
