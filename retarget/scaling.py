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

Orientations: ``R_k(t) = D_k(t) O_k`` (:func:`~retarget.frames.rotation_offsets`; a foot's sole
normal is measured on the frames the human foot is planted). Headings are the human's own, so
any initial yaw works. Without joint orientations the arms get ``rot_weight`` 0.

Every function here reads the clip as mapped once (:func:`~retarget.mapping.map_human`: the points
``P`` and the joint rotations); objects are placed in the robot's world by :mod:`retarget.objects`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.body_height import estimate_height
from pipeline.clip import HumanClip
from pipeline.errors import InputError
from pipeline.foot_contact import detect_foot_contacts
from pipeline.rotations import wxyz_from_rotation
from retarget.frames import Reference, body_axes, driver_rotations, reference_pose, rotation_offsets
from retarget.mapping import G1_ROLES, SIDES, MappedHuman, Mapping, g1_points, g1_rest
from retarget.targets import IKTargets

HEIGHT_RANGE = (1.0, 2.3)
ANKLE_PERCENTILE = 5.0
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
        return {
            "mapping": self.mapping.name,
            "subject_height_m": self.subject_height,
            "height_source": self.height_source,
            "scale_leg": self.leg,
            "scale_trunk": self.trunk,
            "scale_arm": self.arm,
            "height_ratio": g1_rest().height / self.subject_height,
            "reference": self.reference.label,
            "human_m": dict(self.human),
            "robot_m": dict(self.robot),
        }


def check_clip(clip: HumanClip) -> None:
    """At least 2 frames; every object has a geometry."""
    if clip.frames < 2:
        raise InputError(clip.source, "joint_pos", f"the clip has {clip.frames} frame; retargeting needs at least 2")
    for o in clip.objects:
        if o.geometry is None:
            raise InputError(
                o.source or clip.source,
                f"object {o.name} geometry",
                "missing: an object track needs its shape to be retargeted",
            )


def subject_height(clip: HumanClip, override: float | None = None) -> tuple[float, str]:
    """``(height, source)``: the override, else the clip's height, else the head-to-ankle estimate;
    outside 1.0-2.3 m without an override is an :class:`InputError`."""
    if override is not None:
        if not np.isfinite(override) or override <= 0:
            raise InputError(clip.source, "--height", f"must be a positive height in metres, got {override!r}")
        return float(override), "override"
    h, src = clip.subject_height, "clip"
    if h is None:
        h, src = estimate_height(clip.joint_pos, clip.skeleton), "estimate"
    if h is None:
        raise InputError(
            clip.source,
            "subject_height",
            "unknown (none in the clip, no head/ankle joints to estimate it); pass --height M (the subject's height)",
        )
    lo, hi = HEIGHT_RANGE
    if not lo <= h <= hi:
        raise InputError(
            clip.source,
            "subject_height",
            f"{h:.3f} m ({src}) is outside {lo}-{hi} m (wrong units? --units); "
            "pass --height M if the subject really is that tall",
        )
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


def compute_scale(mapped: MappedHuman, *, height_override: float | None = None) -> ScaleInfo:
    """The :class:`ScaleInfo` of the mapped clip (checks the clip and the subject height first):
    factors from its points' :func:`segment_lengths`, ``c`` and ``c'`` (module doc), the reference pose."""
    clip, mapping, P = mapped.clip, mapped.mapping, mapped.points
    check_clip(clip)
    height, src = subject_height(clip, height_override)
    human, robot = segment_lengths(P, mapping), segment_lengths(g1_points(mapping), mapping)
    leg, trunk = robot["leg"] / human["leg"], robot["trunk"] / human["trunk"]
    arm = robot["arm"] / human["arm"] if "arm" in human else trunk
    feet = {s: mapping.body_of_kind("foot", s) for s in SIDES}
    levels = {s: float(np.percentile(P[f][:, 2], ANKLE_PERCENTILE)) for s, f in feet.items()}
    robot_ankle = float(np.mean([g1_rest().pos[f][2] for f in feet.values()]))
    x0, y0 = P["pelvis"][0, :2]
    return ScaleInfo(
        mapping,
        height,
        src,
        human,
        robot,
        float(leg),
        float(trunk),
        float(arm),
        np.array([x0, y0, np.mean(list(levels.values()))]),
        np.array([x0, y0, robot_ankle]),
        levels,
        reference_pose(mapped),
        height_override,
    )


def _place(
    P: dict,
    rot: dict,
    info: ScaleInfo,
    center: np.ndarray,
    levels: dict,
    robot_center: np.ndarray,
    deltas: dict | None = None,
    robot: dict | None = None,
) -> tuple[dict, dict]:
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


def position_offsets(info: ScaleInfo, offsets: dict) -> dict[str, np.ndarray]:
    """The per-body offsets ``delta`` (module doc), from the reference pose's points and drivers
    turned to face +x (rows of ``Q`` = forward, left, up) with its pelvis above the origin."""
    ref, mapping = info.reference, info.mapping
    P, D = ref.points, ref.driver
    L, U, F = body_axes(P, mapping, ref.up)
    Q, origin = np.stack([F[0], L[0], U[0]]), P["pelvis"][0]
    Pa = {k: (v - origin) @ Q.T for k, v in P.items()}
    rot = {b: Q @ D[b] @ offsets[b] for b in mapping.body_names}
    hips = np.mean([Pa[mapping.body_of_kind("thigh", s)][0, 2] for s in SIDES])
    levels = dict.fromkeys(SIDES, float(hips - info.human["leg"]))  # as if the legs were straight
    center, robot_center = (
        np.array([0.0, 0.0, np.mean(list(levels.values()))]),
        np.array([0.0, 0.0, info.robot_center[2]]),
    )
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


def human_to_targets(
    mapped: MappedHuman, *, height_override: float | None = None, scale: ScaleInfo | None = None
) -> IKTargets:
    """G1 :class:`IKTargets` for the mapped clip: ``p'`` = :func:`_place` of its points plus ``R_f delta``,
    ``R_k(t) = D_k(t) O_k`` (module doc); ``foot_contact`` from the human's feet. ``scale``: its
    precomputed :class:`ScaleInfo` (else :func:`compute_scale` with ``height_override``)."""
    clip, mapping = mapped.clip, mapped.mapping
    info = scale or compute_scale(mapped, height_override=height_override)
    D = driver_rotations(mapped.points, mapped.rot, clip.skeleton, mapping)
    contact = foot_contacts(clip)
    offsets = rotation_offsets(info.reference, mapping, sole_normals(D, contact, mapping))
    R = {b: D[b] @ offsets[b] for b in mapping.body_names}
    deltas = position_offsets(info, offsets)
    pos, _ = _place(mapped.points, R, info, info.center, info.foot_levels, info.robot_center, deltas)
    bodies = mapping.body_names
    rot_w = np.array([link.rot_weight for link in mapping.links])
    if clip.joint_quat is None:
        rot_w = np.where([G1_ROLES[b].kind in ARM_KINDS for b in bodies], 0.0, rot_w)
    return IKTargets(
        body_names=bodies,
        pos=np.stack([pos[b] for b in bodies], axis=1),
        quat=_continuous_quats(np.stack([R[b] for b in bodies], axis=1)),
        pos_weight=np.array([link.pos_weight for link in mapping.links]),
        rot_weight=rot_w,
        fps=clip.fps,
        scale=info.leg,
        foot_contact=contact,
    )
