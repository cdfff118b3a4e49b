"""Human to G1 size: scale factors from limb lengths, scaled targets, and objects in the robot's world.

Scale (per clip, computed): the human's segment lengths are the median over frames of the
distances between the mapped joints; the G1's are the same distances between the driven bodies
at ``q = 0`` (:func:`~retarget.mapping.g1_rest`). Three factors, because the G1 is not a scaled
human (long legs, short trunk):

* ``leg   = (hip-knee + knee-ankle)_G1 / (hip-knee + knee-ankle)_human``: stride lengths and
  heights match the robot's legs, so it also scales the root's horizontal travel;
* ``trunk = |shoulder centre - pelvis|_G1 / |...|_human``: torso and shoulders;
* ``arm   = (shoulder-elbow + elbow-wrist)_G1 / (...)_human``: elbows and wrists (full reach
  maps to full reach).

``IKTargets.scale`` is ``leg``. The subject height (the clip's, else estimated from head to
ankle) only guards against wrong units: it must lie in 1.0-2.3 m unless ``height_override`` is
given. The G1/human height ratio is reported beside the factors for comparison.

Positions (``c`` = the root's ground point at frame 0 at the planted-ankle level, the 5th
percentile of the ankle joints' heights, per side for each foot; ``c'`` = the same point at the
G1's ankle height above its sole):

* leg group (pelvis, hips, knees, feet): ``p' = c' + leg (p - c)``: horizontal positions scale
  about the start point (the root's travel scales by ``leg``), heights from the planted ankle,
  so a planted human ankle lands where a planted G1 ankle is;
* trunk group (torso, shoulders): ``p' = pelvis' + trunk (p - p_pelvis)``;
* arm group (elbows, wrists): ``p' = shoulder' + arm (p - p_shoulder)`` (same side);
* plus ``R_f(t) delta``: a constant offset in the target frame of the body's ``offset_frame``,
  calibrated in the reference pose (turned to face +x, legs taken as straight) so that pelvis,
  hips, torso and shoulders land exactly on the G1's ``q = 0`` positions: it absorbs where the
  G1 has its pelvis origin, hip axes, waist and shoulders relative to the human's joints. Knees
  and feet take their hip's horizontal offset in the pelvis's heading frame (the G1's hip width);
  elbows and wrists none (a T-pose arm is not the G1's ``q = 0`` arm).

Orientations: ``R_k(t) = D_k(t) O_k`` (:func:`~retarget.mapping.rotation_offsets`; a foot's sole
normal is measured on the frames the human foot is planted). Headings are the human's own, so
any initial yaw works. Without joint orientations the arms get ``rot_weight`` 0.

Objects (:func:`map_objects`): real size and orientation; the position starts on the leg map
``(c + leg (p - c))_xy, z`` and is integrated frame to frame from the human's motion,

``dp' = (leg dp_xy, dp_z) + w (da' + dp - da - (leg dp_xy, dp_z))``,

``a``/``a'`` the human/mapped mean of the touching mapped joints (the wrists when no per-joint
contacts are given), ``w`` = touched x moving (speed / 0.1 m/s, capped at 1): a carried or pushed
object moves with the robot's hands, a static one never moves, nothing jumps. The whole path is
then shifted horizontally so that, when the object starts moving with the hands (else at the
first touch), it sits relative to them as the human's did. Heights follow the hands only while
the human's object is off the floor (> 1 cm) and the difference decays (0.1 s) once it is back;
the lowest point never goes below the floor (``z = 0`` in both worlds).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.clip import HumanClip, ObjectTrack, Skeleton
from pipeline.errors import InputError
from pipeline.geometry import Chair, MeshGeometry, Primitive
from pipeline.readers.keypoints import estimate_height
from pipeline.rotations import rotation_from_wxyz, wxyz_from_rotation
from retarget.mapping import (
    G1_ROLES, SIDES, Mapping, Reference, body_axes, driver_rotations, g1_points, g1_rest, human_points,
    reference_pose, rotation_offsets,
)  # fmt: skip
from retarget.targets import IKTargets

HEIGHT_RANGE = (1.0, 2.3)
ANKLE_PERCENTILE = 5.0
MOVING_SPEED = 0.1  # m/s at which an object counts as fully moving
LIFT_CLEARANCE = 0.01  # m: an object this far above the floor is off the floor
SETTLE_TAU = 0.1  # s: how fast a resting object's vertical difference decays
ARM_KINDS = ("upper_arm", "forearm", "hand")
GROUP_ORDER = ("leg", "trunk", "arm")  # anchors first


@dataclass(frozen=True)
class ScaleInfo:
    """The scale of one clip (see the module doc). Lengths in metres, keyed ``thigh``, ``shank``,
    ``leg``, ``trunk``, ``upper_arm``, ``forearm``, ``arm``."""

    mapping: Mapping
    subject_height: float
    height_source: str
    human: dict
    robot: dict
    leg: float
    trunk: float
    arm: float
    center: np.ndarray
    robot_center: np.ndarray
    foot_levels: dict
    reference: Reference = field(repr=False)
    height_override: float | None = None

    def summary(self) -> dict:
        """Plain numbers for reports."""
        return {"mapping": self.mapping.name, "subject_height_m": self.subject_height, "height_source": self.height_source,
                "scale_leg": self.leg, "scale_trunk": self.trunk, "scale_arm": self.arm,
                "height_ratio": g1_rest().height / self.subject_height, "reference": self.reference.label,
                "human_m": dict(self.human), "robot_m": dict(self.robot)}  # fmt: skip


def check_clip(clip: HumanClip) -> None:
    """At least 2 frames; every object has a geometry."""
    if clip.frames < 2:
        raise InputError(clip.source, "joint_pos", f"the clip has {clip.frames} frame; retargeting needs at least 2")
    for o in clip.objects:
        if o.geometry is None:
            raise InputError(o.source or clip.source, f"object {o.name} geometry", "missing: an object track needs its shape to be retargeted")


def subject_height(clip: HumanClip, override: float | None = None) -> tuple[float, str]:
    """``(height, source)``: the override, else the clip's height, else the head-to-ankle estimate;
    outside 1.0-2.3 m without an override is an :class:`InputError`."""
    if override is not None:
        if not np.isfinite(override) or override <= 0:
            raise InputError(clip.source, "height_override", f"must be a positive height in metres, got {override!r}")
        return float(override), "override"
    h, src = clip.subject_height, "clip"
    if h is None:
        h, src = estimate_height(clip.joint_pos, clip.skeleton), "estimate"
    if h is None:
        raise InputError(clip.source, "subject_height", "unknown (none in the clip, no head/ankle joints to estimate it); pass height_override")
    lo, hi = HEIGHT_RANGE
    if not lo <= h <= hi:
        raise InputError(clip.source, "subject_height", f"{h:.3f} m ({src}) is outside {lo}-{hi} m (wrong units?); "
                         "pass height_override if the subject really is that tall")  # fmt: skip
    return float(h), src


def segment_lengths(P: dict[str, np.ndarray], mapping: Mapping) -> dict[str, float]:
    """Median (over frames) segment lengths, both sides averaged (see the module doc)."""

    def dist(a: str | None, b: str | None) -> float:
        return float(np.median(np.linalg.norm(P[a] - P[b], axis=-1)))

    def both(k1: str, k2: str) -> float:
        return float(np.mean([dist(mapping.body_of_kind(k1, s), mapping.body_of_kind(k2, s)) for s in SIDES]))

    out = {"thigh": both("thigh", "shank"), "shank": both("shank", "foot")}
    out["leg"] = out["thigh"] + out["shank"]
    shoulders = [mapping.body_of_kind("upper_arm", s) for s in SIDES]
    top = np.mean([P[b] for b in shoulders], axis=0) if all(shoulders) else P["torso_link>"]
    out["trunk"] = float(np.median(np.linalg.norm(top - P["pelvis"], axis=-1)))
    if all(mapping.body_of_kind(k, s) for k in ARM_KINDS for s in SIDES):
        out["upper_arm"], out["forearm"] = both("upper_arm", "forearm"), both("forearm", "hand")
        out["arm"] = out["upper_arm"] + out["forearm"]
    return out


def _joint_rotations(clip: HumanClip) -> np.ndarray | None:
    if clip.joint_quat is None:
        return None
    return rotation_from_wxyz(clip.joint_quat.reshape(-1, 4)).as_matrix().reshape(clip.frames, -1, 3, 3)


def compute_scale(clip: HumanClip, mapping: Mapping, *, height_override: float | None = None,
                  _rot: np.ndarray | None = None) -> ScaleInfo:  # fmt: skip
    """The clip's :class:`ScaleInfo` (checks the clip and the subject height first)."""
    check_clip(clip)
    height, src = subject_height(clip, height_override)
    rot = _joint_rotations(clip) if _rot is None else _rot
    P = human_points(clip.joint_pos, clip.skeleton, mapping)
    human, robot = segment_lengths(P, mapping), segment_lengths(g1_points(mapping), mapping)
    leg, trunk = robot["leg"] / human["leg"], robot["trunk"] / human["trunk"]
    arm = robot["arm"] / human["arm"] if "arm" in human else trunk
    feet = {s: mapping.body_of_kind("foot", s) for s in SIDES}
    levels = {s: float(np.percentile(P[f][:, 2], ANKLE_PERCENTILE)) for s, f in feet.items()}
    robot_ankle = float(np.mean([g1_rest().pos[f][2] for f in feet.values()]))
    x0, y0 = P["pelvis"][0, :2]
    return ScaleInfo(mapping, height, src, human, robot, float(leg), float(trunk), float(arm),
                     np.array([x0, y0, np.mean(list(levels.values()))]), np.array([x0, y0, robot_ankle]), levels,
                     reference_pose(clip.joint_pos, rot, clip.skeleton, mapping), height_override)  # fmt: skip


def _place(P: dict, rot: dict, info: ScaleInfo, center: np.ndarray, levels: dict, robot_center: np.ndarray,
           deltas: dict | None = None, robot: dict | None = None) -> tuple[dict, dict]:  # fmt: skip
    """Target positions per body (the chain in the module doc; a foot's height counts from its own
    side's planted-ankle level ``levels[side]``) and, when ``deltas`` is None, the offsets that
    put frame 0 exactly on ``robot`` (calibration)."""
    mapping, out, cal = info.mapping, {}, {}
    for b in sorted(mapping.body_names, key=lambda b: GROUP_ORDER.index(G1_ROLES[b].group)):
        role = G1_ROLES[b]
        if role.group == "leg":
            c = center if role.kind != "foot" else np.array([*center[:2], levels[role.side]])
            base = robot_center + info.leg * (P[b] - c)
        elif role.group == "trunk":
            base = out["pelvis"] + info.trunk * (P[b] - P["pelvis"])
        else:
            sh = mapping.body_of_kind("upper_arm", role.side)
            base = out[sh] + info.arm * (P[b] - P[sh])
        f = role.offset_frame if role.offset_frame in rot else None
        if f is None:
            out[b] = base
            continue
        if deltas is None and role.offset_body is None:
            cal[b] = rot[f][0].T @ (robot[b][0] - base[0])
        d = (cal if deltas is None else deltas)[role.offset_body or b]
        frame = rot[f] if role.offset_body is None else _heading(rot[f])
        if role.offset_body is not None:  # a knee or foot moves with its hip, sideways and fore-aft only
            d = d * np.array([1.0, 1.0, 0.0])
        out[b] = base + frame @ d
    return out, cal


def _heading(R: np.ndarray) -> np.ndarray:
    """The yaw-only part ``Rz(psi)`` of rotations ``(T, 3, 3)``, from their y (left) axis:
    ``psi = atan2(y_y, y_x) - pi/2`` (well defined while the body is not rolled on its side)."""
    psi = np.arctan2(R[:, 1, 1], R[:, 0, 1]) - np.pi / 2
    c, s = np.cos(psi), np.sin(psi)
    out = np.zeros_like(R)
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1], out[:, 2, 2] = c, -s, s, c, 1.0
    return out


def position_offsets(info: ScaleInfo, skel: Skeleton, offsets: dict) -> dict[str, np.ndarray]:
    """The per-body offsets ``delta`` (module doc), from the reference pose turned to face +x
    (rows of ``Q`` = forward, left, up) with its pelvis above the origin."""
    ref, mapping = info.reference, info.mapping
    P = human_points(ref.pos[None], skel, mapping)
    L, U, F = body_axes(P, mapping, ref.up)
    Q, origin = np.stack([F[0], L[0], U[0]]), P["pelvis"][0]
    Pa = {k: (v - origin) @ Q.T for k, v in P.items()}
    D = driver_rotations(ref.pos[None], None if ref.rot is None else ref.rot[None], skel, mapping)
    rot = {b: Q @ D[b] @ offsets[b] for b in mapping.body_names}
    hips = np.mean([Pa[mapping.body_of_kind("thigh", s)][0, 2] for s in SIDES])
    levels = dict.fromkeys(SIDES, float(hips - info.human["leg"]))  # as if the legs were straight
    center, robot_center = np.array([0.0, 0.0, np.mean(list(levels.values()))]), np.array([0.0, 0.0, info.robot_center[2]])
    return _place(Pa, rot, info, center, levels, robot_center, None, g1_points(mapping))[1]


def _continuous_quats(R: np.ndarray) -> np.ndarray:
    """wxyz ``(T, K, 4)`` from rotations ``(T, K, 3, 3)``, signs chosen so consecutive frames agree."""
    T, K = R.shape[:2]
    q = wxyz_from_rotation(Rotation.from_matrix(R.reshape(-1, 3, 3))).reshape(T, K, 4)
    flip = np.where(np.sum(q[1:] * q[:-1], -1) < 0, -1.0, 1.0)
    q[1:] *= np.cumprod(flip, axis=0)[..., None]
    return q


def foot_contacts(clip: HumanClip) -> np.ndarray | None:
    """``(T, 2)`` human foot-ground contact (left, right) from :mod:`pipeline.foot_contact`; None
    when the skeleton's foot joints are not recognisable there."""
    from pipeline.foot_contact import detect_foot_contacts

    try:
        return detect_foot_contacts(clip).both
    except ValueError:
        return None


def sole_normals(D: dict, contact: np.ndarray | None, mapping: Mapping) -> dict[str, np.ndarray]:
    """Per foot body, the world's up in the foot driver's frame, averaged over the frames the
    foot is planted: ``normalize(sum_t D(t)^T z)`` (feet without planted frames are left out)."""
    out = {}
    for i, s in enumerate(SIDES):
        foot = mapping.body_of_kind("foot", s)
        if contact is not None and contact[:, i].any():
            u = D[foot][contact[:, i], 2, :].sum(axis=0)  # rows of D^T z = third row of D
            out[foot] = u / np.linalg.norm(u)
    return out


def human_to_targets(clip: HumanClip, mapping: Mapping, *, height_override: float | None = None,
                     scale: ScaleInfo | None = None) -> IKTargets:  # fmt: skip
    """G1 :class:`IKTargets` for ``clip`` (positions, orientations and weights as in the module
    doc; ``foot_contact`` from the human's feet). ``scale``: a precomputed :class:`ScaleInfo`."""
    rot = _joint_rotations(clip)
    info = scale or compute_scale(clip, mapping, height_override=height_override, _rot=rot)
    D = driver_rotations(clip.joint_pos, rot, clip.skeleton, mapping)
    contact = foot_contacts(clip)
    offsets = rotation_offsets(info.reference, clip.skeleton, mapping, sole_normals(D, contact, mapping))
    R = {b: D[b] @ offsets[b] for b in mapping.body_names}
    P = human_points(clip.joint_pos, clip.skeleton, mapping)
    deltas = position_offsets(info, clip.skeleton, offsets)
    pos, _ = _place(P, R, info, info.center, info.foot_levels, info.robot_center, deltas)
    bodies = mapping.body_names
    rot_w = np.array([link.rot_weight for link in mapping.links])
    if clip.joint_quat is None:
        rot_w = np.where([G1_ROLES[b].kind in ARM_KINDS for b in bodies], 0.0, rot_w)
    return IKTargets(
        body_names=bodies, pos=np.stack([pos[b] for b in bodies], axis=1),
        quat=_continuous_quats(np.stack([R[b] for b in bodies], axis=1)),
        pos_weight=np.array([link.pos_weight for link in mapping.links]), rot_weight=rot_w,
        fps=clip.fps, scale=info.leg, foot_contact=contact,
    )  # fmt: skip


# --- Objects ---------------------------------------------------------------------------------------


def _box_corners(half: np.ndarray, centre=np.zeros(3)) -> np.ndarray:
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    return centre + signs * half


def object_bottom(geometry, pose: np.ndarray) -> np.ndarray:
    """``(T,)`` lowest world height of the object at each pose (exact for boxes, spheres,
    capsules and meshes (their convex hull vertices); cylinders with their larger radius)."""
    R = rotation_from_wxyz(pose[:, 3:]).as_matrix()
    z = pose[:, 2]
    if isinstance(geometry, Primitive) and geometry.kind != "box":
        s, sc = geometry.size, np.asarray(geometry.scale)
        if geometry.kind == "sphere":
            return z - s[0] * sc.max()
        axial = np.abs(R[:, 2, 2]) * s[1] * sc[2]
        if geometry.kind == "capsule":
            return z - axial - s[0] * sc.max()
        return z - axial - s[0] * sc[:2].max() * np.sqrt(np.maximum(0.0, 1.0 - R[:, 2, 2] ** 2))
    if isinstance(geometry, Primitive):
        pts = _box_corners(geometry.half_extents)
    elif isinstance(geometry, MeshGeometry):
        from pipeline.collision_mesh import load_mesh

        pts = load_mesh(geometry.path).convex_hull.vertices * np.asarray(geometry.scale)
    elif isinstance(geometry, Chair):
        pts = np.concatenate([_box_corners(p.half_extents, c) for _, p, c in geometry.parts()])
    else:
        raise TypeError(f"unknown object geometry {type(geometry).__name__}")
    return z + (R[:, 2, :] @ pts.T).min(axis=1)


def _smooth(x: np.ndarray, frames: int) -> np.ndarray:
    """Centred moving average over ``frames`` (edges padded with the end values)."""
    if frames < 2:
        return x.astype(float)
    pad = np.pad(x.astype(float), (frames // 2, frames - 1 - frames // 2), mode="edge")
    return np.convolve(pad, np.ones(frames) / frames, mode="valid")


def _anchors(clip: HumanClip, targets: IKTargets, mapping: Mapping) -> tuple[np.ndarray, ...]:
    """The interaction anchor: the mean of the touching mapped joints (per-joint ``clip.contacts``;
    the wrists when none touches). Returns its human and mapped positions ``(T, 3)``, their
    displacements from ``t-1`` taken over frame ``t``'s joints (row 0 zero), and whether frame
    ``t`` has an anchor ``(T,)``."""
    idx = [clip.skeleton.index(link.joint) for link in mapping.links]
    hands = np.array([G1_ROLES[b].kind == "hand" for b in mapping.body_names])
    T = clip.frames
    mask = clip.contacts[:, idx] if clip.contacts is not None else np.zeros((T, len(idx)), bool)
    mask = np.where(mask.any(axis=1, keepdims=True), mask, hands[None])
    w = mask / np.maximum(mask.sum(axis=1, keepdims=True), 1)
    out = []
    for X in (clip.joint_pos[:, idx], targets.pos):
        step = np.zeros((T, 3))
        step[1:] = np.einsum("tk,tkc->tc", w[1:], np.diff(X, axis=0))
        out += [np.einsum("tk,tkc->tc", w, X), step]
    return out[0], out[2], out[1], out[3], mask.any(axis=1)


def _map_track(o: ObjectTrack, clip: HumanClip, info: ScaleInfo, anchors) -> ObjectTrack:
    """One object in the robot's world (module doc): integrate, then shift horizontally so that
    when it starts moving with the touching joints (or else at the first touch) it sits where the
    human's sat relative to them."""
    p, T, fps = o.pose[:, :3], o.frames, clip.fps
    ah, ar, dh, dr, anchored = anchors
    touched = o.contact if o.contact is not None else (
        clip.contacts.any(axis=1) if clip.contacts is not None else np.zeros(T, bool))  # fmt: skip
    speed = np.linalg.norm(np.gradient(p, axis=0), axis=1) * fps
    n = max(1, int(round(0.1 * fps)))
    w = _smooth(touched & anchored, n) * np.clip(_smooth(speed, n) / MOVING_SPEED, 0.0, 1.0)
    bottom = object_bottom(o.geometry, o.pose)
    resting = 1.0 - _smooth(bottom > LIFT_CLEARANCE, n)
    decay = 1.0 - np.exp(-1.0 / (fps * SETTLE_TAU))
    c, s = info.center[:2], info.leg
    out = p.copy()
    out[0, :2] = c + s * (p[0, :2] - c)
    dz = 0.0
    for t in range(1, T):
        step = p[t] - p[t - 1]
        free_xy = s * step[:2]
        out[t, :2] = out[t - 1, :2] + free_xy + w[t] * (dr[t, :2] + step[:2] - dh[t, :2] - free_xy)
        dz = (dz + w[t] * (1.0 - resting[t]) * (dr[t, 2] - dh[t, 2])) * (1.0 - decay * resting[t])
        dz = max(dz, min(0.0, bottom[t]) - bottom[t])  # never below the floor (nor lower than the human's)
        out[t, 2] = p[t, 2] + dz
    first = np.flatnonzero(w >= 0.5) if (w >= 0.5).any() else np.flatnonzero(touched & anchored)
    if first.size:  # where it starts moving with the anchor (else first touched), as the human's
        t0 = first[0]
        out[:, :2] += (ar[t0] + p[t0] - ah[t0])[:2] - out[t0, :2]
    return replace(o, pose=np.concatenate([out, o.pose[:, 3:]], axis=1))


def map_objects(clip: HumanClip, scale_info: ScaleInfo, targets: IKTargets | None = None) -> tuple[ObjectTrack, ...]:
    """The clip's objects in the robot's world: real size and orientation, placement following the
    scaled interaction (module doc). ``targets``: the clip's :func:`human_to_targets` (computed
    when not given)."""
    check_clip(clip)
    if not clip.objects:
        return ()
    if targets is None:
        targets = human_to_targets(clip, scale_info.mapping, height_override=scale_info.height_override, scale=scale_info)
    anchors = _anchors(clip, targets, scale_info.mapping)
    return tuple(_map_track(o, clip, scale_info, anchors) for o in clip.objects)
