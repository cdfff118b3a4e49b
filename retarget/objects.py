"""The clip's objects in the robot's world.

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

from dataclasses import replace

import numpy as np

from pipeline.clip import HumanClip, ObjectTrack
from pipeline.collision_mesh import load_mesh
from pipeline.geometry import Chair, MeshGeometry, Primitive
from pipeline.rotations import rotation_from_wxyz
from retarget.mapping import G1_ROLES, MappedHuman, Mapping
from retarget.scaling import ScaleInfo, check_clip, human_to_targets
from retarget.targets import IKTargets

MOVING_SPEED = 0.1  # m/s at which an object counts as fully moving
LIFT_CLEARANCE = 0.01  # m: an object this far above the floor is off the floor
SETTLE_TAU = 0.1  # s: how fast a resting object's vertical difference decays


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
    touched = (
        o.contact
        if o.contact is not None
        else (clip.contacts.any(axis=1) if clip.contacts is not None else np.zeros(T, bool))
    )
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


def map_objects(
    mapped: MappedHuman, scale_info: ScaleInfo, targets: IKTargets | None = None
) -> tuple[ObjectTrack, ...]:
    """The mapped clip's objects in the robot's world: real size and orientation, placement following
    the scaled interaction (module doc). ``targets``: the clip's :func:`human_to_targets` (computed
    when not given)."""
    clip = mapped.clip
    check_clip(clip)
    if not clip.objects:
        return ()
    if targets is None:
        targets = human_to_targets(mapped, height_override=scale_info.height_override, scale=scale_info)
    anchors = _anchors(clip, targets, scale_info.mapping)
    return tuple(_map_track(o, clip, scale_info, anchors) for o in clip.objects)
