"""Segment frames, the standing reference pose and the rotation offsets between human and G1 frames.

Rotation offsets. A segment frame ``G = frame_from(a, b)`` is built from two directions by the
same recipe for human and G1 (:func:`segment_frames`). For body ``k`` driven by joint ``j``::

    O_k = D_k(ref)^T  G_h,k(ref)  G_r,k^T  R_r,k,        target  R_k(t) = D_k(t) O_k

``D_k`` the driver (the joint's global rotation, or a frame from positions), ``G_h`` the human
segment frame in the reference pose, ``G_r``/``R_r`` the G1's segment frame/body rotation at
``q = 0``. Segment directions carry over exactly; in the reference pose every target is the G1's
``q = 0`` rotation (up to the heading) where the human segment is posed like the G1's.

Everything here reads the clip's points ``P`` as mapped once (:func:`~retarget.mapping.map_human`);
the reference pose carries its own points and drivers (:class:`Reference`), taken from the clip's
at the standing frame or mapped once from the rest pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.clip import Skeleton
from retarget.mapping import G1_ROLES, SIDES, MappedHuman, Mapping, Z, g1_points, g1_rest, human_points


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _perp(v: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``v`` without its component along the unit vector ``u``."""
    return v - np.sum(v * u, -1, keepdims=True) * u


def frame_from(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotations ``(..., 3, 3)``, columns ``e1 = a/|a|``, ``e2`` = ``b`` made orthogonal to ``e1``
    (any perpendicular if ``b`` is parallel to ``a``), ``e3 = e1 x e2``."""
    e1, alt = _unit(a), np.where(np.abs(_unit(a)[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    b = _perp(b, e1)
    e2 = _unit(np.where(np.linalg.norm(b, axis=-1, keepdims=True) < 1e-9, np.cross(e1, alt), b))
    return np.stack([e1, e2, np.cross(e1, e2)], axis=-1)


def body_axes(P: dict[str, np.ndarray], mapping: Mapping, up: np.ndarray | None = None):
    """``(L, U, F)`` each ``(T, 3)``: left (right hip -> left hip); up (``up``, else pelvis -> the
    torso's joint, the chest), made orthogonal to L; forward ``L x U``."""
    L = _unit(P[mapping.body_of_kind("thigh", "left")] - P[mapping.body_of_kind("thigh", "right")])
    U = _unit(_perp(np.broadcast_to(up, L.shape) if up is not None else P["torso_link"] - P["pelvis"], L))
    return L, U, np.cross(L, U)


def _flexion_side(P: dict, mapping: Mapping, side: str, upper: bool, forward: np.ndarray) -> np.ndarray:
    """Where an arm segment bends to at the elbow: the upper arm towards the forearm, forearm and
    hand towards the upper arm, orthogonal to the segment; ``forward`` as the elbow straightens
    (blended in between 29 and 12 degrees of bend)."""
    sh, el, wr = (mapping.body_of_kind(k, side) for k in ("upper_arm", "forearm", "hand"))
    if sh is None or el is None or wr is None:
        return forward
    seg, other = (P[el] - P[sh], P[wr] - P[el]) if upper else (P[wr] - P[el], P[sh] - P[el])
    u = _unit(seg)
    beta = np.clip((np.linalg.norm(np.cross(u, _unit(other)), axis=-1, keepdims=True) - 0.2) / 0.3, 0.0, 1.0)
    return _unit(beta * _unit(_perp(other, u)) + (1.0 - beta) * forward)


def segment_frames(
    P: dict[str, np.ndarray], mapping: Mapping, up: np.ndarray | None = None, calibration: bool = True
) -> dict[str, np.ndarray]:
    """Segment frames ``(T, 3, 3)`` from points ``P`` (:func:`human_points` / :func:`g1_points`);
    ``d`` the body's segment direction, ``L, U, F`` = :func:`body_axes`. Thigh, shank ``(d, L)``;
    arm segments ``(d, flexion side)``. With ``calibration`` (a standing pose: trunk upright and
    square, soles level): pelvis, torso ``(L, U)``, foot ``(U, d)``; without (frames from positions
    alone): pelvis ``(L, d)``, torso ``(shoulder line, d)``, foot ``(d, L)``."""
    L, U, F = body_axes(P, mapping, up)
    ls, rs = mapping.body_of_kind("upper_arm", "left"), mapping.body_of_kind("upper_arm", "right")
    out = {}
    for b in mapping.body_names:
        role, d = G1_ROLES[b], P[b + ">"] - P[b]
        if role.kind in ("pelvis", "torso") and calibration:
            out[b] = frame_from(L, U)
        elif role.kind == "pelvis":
            out[b] = frame_from(L, d)
        elif role.kind == "torso":
            out[b] = frame_from(P[ls] - P[rs] if ls and rs else L, d)
        elif role.kind == "foot" and calibration:
            out[b] = frame_from(U, d)
        elif role.kind in ("thigh", "shank", "foot"):
            out[b] = frame_from(d, L)
        else:
            out[b] = frame_from(d, _flexion_side(P, mapping, role.side, role.kind == "upper_arm", F))
    return out


@dataclass(frozen=True)
class Reference:
    """The standing pose offsets are calibrated in: joint positions ``(J, 3)``, global rotations
    ``(J, 3, 3)`` (None without orientations), ``up`` (None: the body's own pelvis -> chest, for a
    rest pose not placed in the world), a label, and the pose as one frame: its points ``P``
    (:func:`~retarget.mapping.human_points`, ``(1, 3)`` each) and drivers ``D_k(ref)``
    (:func:`driver_rotations`, ``(1, 3, 3)`` each)."""

    pos: np.ndarray
    rot: np.ndarray | None
    up: np.ndarray | None
    label: str
    points: dict[str, np.ndarray] = field(repr=False)
    driver: dict[str, np.ndarray] = field(repr=False)


def rest_positions(joint_pos: np.ndarray, joint_rot: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """The rest pose ``(J, 3)``: all global rotations identity, bone offsets
    ``o_j = median_t R_parent(t)^T (p_j(t) - p_parent(t))``, ``p_j = p_parent + o_j``."""
    rest = np.zeros((len(skeleton.parents), 3))
    for j, p in enumerate(skeleton.parents):
        if p >= 0:
            rest[j] = rest[p] + np.median(
                np.einsum("tba,tb->ta", joint_rot[:, p], joint_pos[:, j] - joint_pos[:, p]), axis=0
            )
    return rest


def _cosines(P: dict, mapping: Mapping, kinds: tuple[str, ...], U: np.ndarray) -> np.ndarray:
    """``(T, 2, len(kinds))`` cosines between ``U`` and the segment directions of both sides."""
    bodies = [[mapping.body_of_kind(k, s) for k in kinds] for s in SIDES]
    return np.stack([np.stack([np.sum(_unit(P[b + ">"] - P[b]) * U, -1) for b in row], -1) for row in bodies], 1)


def standing_frame(P: dict[str, np.ndarray], mapping: Mapping) -> int:
    """The frame of the clip's points ``P`` most like standing: score ``-sum cos(thighs and shanks, z)
    + 2 cos(pelvis -> chest, z) - 5 |z_ankle,left - z_ankle,right| / leg length``, maximised."""
    ankles = [P[mapping.body_of_kind("foot", s)] for s in SIDES]
    leg = max(float(np.median(np.linalg.norm(P["pelvis"] - ankles[0], axis=-1))), 1e-6)
    trunk = _unit(P["torso_link"] - P["pelvis"])[:, 2]
    score = (
        -_cosines(P, mapping, ("thigh", "shank"), Z).sum(axis=(1, 2))
        + 2 * trunk
        - 5 * np.abs(ankles[0][:, 2] - ankles[1][:, 2]) / leg
    )
    return int(np.argmax(score))


def reference_pose(mapped: MappedHuman) -> Reference:
    """The rest pose (:func:`rest_positions`) when it stands (thighs and shanks within 37 degrees
    of its own pelvis -> chest axis reversed, feet within 37 degrees of level: SMPL, OMOMO, PyMO
    T-poses), else the clip's :func:`standing_frame` ``t`` with world up and the clip's points
    ``P(t)`` (LAFAN1's zero-rotation pose is no standing pose; clips without orientations have no
    rest pose)."""
    joint_pos, joint_rot, skeleton, mapping = mapped.clip.joint_pos, mapped.rot, mapped.clip.skeleton, mapped.mapping
    if joint_rot is not None:
        rest = rest_positions(joint_pos, joint_rot, skeleton)
        P = human_points(rest[None], skeleton, mapping)
        U = body_axes(P, mapping)[1]
        if (_cosines(P, mapping, ("thigh", "shank"), U) < -0.8).all() and (
            np.abs(_cosines(P, mapping, ("foot",), U)) < 0.6
        ).all():
            R = np.broadcast_to(np.eye(3), (len(rest), 3, 3))
            return Reference(rest, R, None, "rest pose", P, driver_rotations(P, R[None], skeleton, mapping))
    t = standing_frame(mapped.points, mapping)
    P, R = {k: v[t : t + 1] for k, v in mapped.points.items()}, None if joint_rot is None else joint_rot[t]
    D = driver_rotations(P, None if R is None else R[None], skeleton, mapping)
    return Reference(joint_pos[t], R, Z, f"frame {t}", P, D)


def driver_rotations(
    P: dict[str, np.ndarray], joint_rot: np.ndarray | None, skeleton: Skeleton, mapping: Mapping
) -> dict[str, np.ndarray]:
    """``D_k(t)`` ``(T, 3, 3)`` per body: the driving joint's global rotation ``joint_rot[:, j]``, or
    without orientations the frame from the points ``P`` (:func:`segment_frames`, ``calibration=False``)."""
    if joint_rot is not None:
        return {link.body: joint_rot[:, skeleton.index(link.joint)] for link in mapping.links}
    return segment_frames(P, mapping, None, calibration=False)


def rotation_offsets(
    ref: Reference, mapping: Mapping, sole_up: dict[str, np.ndarray] | None = None
) -> dict[str, np.ndarray]:
    """``O_k = D_k(ref)^T G_h,k(ref) G_r,k^T R_r,k`` per body ``(3, 3)`` (module doc).

    ``sole_up[foot]``: the sole's normal in the foot driver's own frame, measured where the foot
    is planted; it replaces the reference's up in the foot recipe, so a planted human foot gives
    a level G1 foot whatever the reference's ankle angle."""
    P, D = ref.points, ref.driver
    Gh = segment_frames(P, mapping, ref.up)
    for b, u in (sole_up or {}).items():
        Gh[b] = D[b] @ frame_from(u, D[b][0].T @ (P[b + ">"][0] - P[b][0]))
    Gr, R = segment_frames(g1_points(mapping), mapping, Z), g1_rest().rot
    return {b: D[b][0].T @ Gh[b][0] @ Gr[b][0].T @ R[b] for b in mapping.body_names}
