"""Foot targets of the feasible reference's IK (:mod:`physicalize.feasible`): footsteps in stance, the
reference with a blended footstep offset elsewhere.

During each stance run of the reference's support schedule the foot is pinned to one **footstep**: the
reference's horizontal position and heading at the run's slowest frame, sole flat on the floor (``z = 0``;
the whole-body controller also holds stance feet flat), over the run's **planted** frames (those where
the reference foot is within :attr:`~physicalize.feasible.FeasibleConfig.footstep_tolerance` of the
footstep: a low foot still sliding in to land or out to lift off is not pinned). Other frames follow the
reference with an offset (position and rotation vector) blended linearly from the previous footstep's to
the next one's, so a foot lifts off and lands on its footsteps without a jump.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from physicalize.reference import Reference
from pipeline.foot_contact import runs
from pipeline.rotations import yaw_of

Footstep = tuple[int, int, np.ndarray, Rotation]  # (first planted frame, stop, footstep position, footstep rotation)


@dataclass
class FootTargets:
    """Per-frame foot body targets and where they are footsteps (``planted``: the IK holds them exactly)."""

    pos: np.ndarray  # (T, 2, 3)
    quat: np.ndarray  # (T, 2, 4) wxyz
    planted: np.ndarray  # (T, 2) bool, a subset of the reference's stance


def _yaw_rotation(quat_wxyz: np.ndarray) -> Rotation:
    return Rotation.from_euler("z", yaw_of(quat_wxyz))


def _rot(quat_wxyz: np.ndarray) -> Rotation:
    return Rotation.from_quat(np.asarray(quat_wxyz)[..., [1, 2, 3, 0]])


def _wxyz(r: Rotation) -> np.ndarray:
    return r.as_quat()[..., [3, 0, 1, 2]]


def foot_targets(ref: Reference, sole_z: np.ndarray, tolerance: float = 0.02, clearance: float = 0.0) -> FootTargets:
    """Footsteps in stance, the reference plus a blended footstep offset elsewhere (module docstring).

    With ``clearance > 0`` a foot swinging between two footsteps (the reference's schedule) whose sole
    never rises ``clearance`` above the floor is made level (its blended heading, no pitch or roll: the
    tracker lands feet flat), with its sole at least ``clearance sin^2(pi s)`` above the floor (``s``:
    0 -> 1 from the frame before the swing to the frame after it): a human's toe-off and heel-strike
    swings keep the pitched G1 sole 0.5-2 cm off the floor, and a flat foot that low scuffs and lands
    early. Swings that clear it are left as they are.

    ``sole_z[k]``: the sole's height in foot ``k``'s body frame (negative), so a flat foot on the floor
    has its origin at ``-sole_z``. A stance run's footstep holds over its **planted** frames: the
    contiguous frames around the run's slowest one where the reference foot is within ``tolerance``
    (horizontally) of the footstep. A stance run whose reference foot slides further (a low, fast
    foot the schedule counts as support) is followed like a swing outside those frames.
    """
    T = ref.frames
    pos, quat = ref.foot_pos.copy(), ref.foot_quat.copy()
    planted = np.zeros((T, 2), bool)
    for k in range(2):
        steps = _footsteps(ref, k, -sole_z[k], tolerance)
        for a, b, p, r in steps:
            pos[a:b, k], quat[a:b, k], planted[a:b, k] = p, _wxyz(r), True
        ref_rot = _rot(ref.foot_quat[:, k])
        for before, after in zip([None, *steps], [*steps, None]):
            a0, a1 = (before[1] if before else 0), (after[0] if after else T)
            if a1 <= a0 or (before is None and after is None):
                continue
            _blend(ref, k, ref_rot, before, after, pos, quat)
            if clearance > 0 and before is not None and after is not None:
                _lift_low_swings(ref, k, a0, a1, -sole_z[k], clearance, pos, quat)
    return FootTargets(pos, quat, planted)


def _footsteps(ref: Reference, k: int, height: float, tolerance: float) -> list[Footstep]:
    """Foot ``k``'s footsteps, one per stance run: at the run's slowest frame, its origin ``height`` above the
    floor, level at the reference's heading, held over the planted frames around it."""
    T, dt = ref.frames, 1.0 / ref.fps
    speed = np.linalg.norm(np.gradient(ref.foot_pos[:, k, :2], dt, axis=0), axis=-1) if T > 1 else np.zeros(T)
    steps = []
    for s, e in runs(ref.stance[:, k]):
        i = s + int(np.argmin(speed[s:e]))
        p = np.array([ref.foot_pos[i, k, 0], ref.foot_pos[i, k, 1], height])
        near = np.linalg.norm(ref.foot_pos[s:e, k, :2] - p[:2], axis=1) <= tolerance
        a = i
        while a > s and near[a - 1 - s]:
            a -= 1
        b = i + 1
        while b < e and near[b - s]:
            b += 1
        steps.append((a, b, p, _yaw_rotation(ref.foot_quat[i, k])))
    return steps


def _blend(
    ref: Reference,
    k: int,
    ref_rot: Rotation,
    before: Footstep | None,
    after: Footstep | None,
    pos: np.ndarray,
    quat: np.ndarray,
) -> None:
    """Foot ``k``'s targets between two footsteps (either may be missing: the clip's ends), in place: the
    reference moved by the footstep offsets at the last planted frame before and the first planted frame
    after, blended linearly."""
    a0, a1 = (before[1] if before else 0), (after[0] if after else ref.frames)
    frames = np.arange(a0, a1)
    d0 = (before[2] - ref.foot_pos[a0 - 1, k], (before[3] * ref_rot[a0 - 1].inv()).as_rotvec()) if before else None
    d1 = (after[2] - ref.foot_pos[a1, k], (after[3] * ref_rot[a1].inv()).as_rotvec()) if after else None
    d0, d1 = d0 or d1, d1 or d0
    alpha = ((frames - (a0 - 1)) / (a1 - a0 + 1))[:, None]  # 0 at the last planted frame, 1 at the next
    pos[frames, k] = ref.foot_pos[frames, k] + (1 - alpha) * d0[0] + alpha * d1[0]
    quat[frames, k] = _wxyz(Rotation.from_rotvec((1 - alpha) * d0[1] + alpha * d1[1]) * ref_rot[frames])


def _lift_low_swings(
    ref: Reference, k: int, a0: int, a1: int, height: float, clearance: float, pos: np.ndarray, quat: np.ndarray
) -> None:
    """The swings of foot ``k`` in ``[a0, a1)`` whose reference sole stays below ``clearance``, made level and
    lifted to ``clearance sin^2(pi s)`` at least (``height``: the foot origin's height on the floor), in place."""
    for s, e in runs(~ref.stance[a0:a1, k]):
        sw = np.arange(a0 + s, a0 + e)
        if ref.sole_height[sw, k].max() >= clearance:
            continue
        quat[sw, k] = [_wxyz(_yaw_rotation(q)) for q in quat[sw, k]]
        lift = clearance * np.sin(np.pi * (sw - (a0 + s - 1)) / (e - s + 1)) ** 2
        pos[sw, k, 2] = np.maximum(pos[sw, k, 2], height + lift)
