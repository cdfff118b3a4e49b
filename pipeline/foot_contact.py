"""Human foot-ground contact from joint positions alone: a foot is down when it is low and still.

For each side (left, right) the detector uses the foot's joints (:func:`find_foot_joints`): the
ankle and the toe joint, found by name (SMPL/SMPL-H ``left_ankle`` + ``left_foot``; LAFAN/BVH
``LeftFoot`` + ``LeftToe``/``LeftToeBase``; any other name holding a side word and
foot/ankle/toe).

The math, for a clip of ``T`` frames at ``fps`` with joint heights ``z_j(t)`` (z-up) and
horizontal positions ``p_j(t) = (x_j, y_j)``:

* **floor per joint role.** A joint sits at a fixed height above the sole when the foot is
  flat (an ankle ~8 cm, a toe joint ~2.5 cm), so each role (ankle, toe) gets its own planted
  level ``r_role`` = the ``q``-th percentile (``q`` = 5) of the heights of that role's joints of
  both feet over the whole clip. Nothing is hard-coded: the estimate moves with the clip's
  floor and the skeleton. ``floor_height`` (reported) is the ``q``-th percentile of the
  per-frame lowest foot joint, ``min_j z_j(t)``: the level the lowest foot joint is at when
  planted (the floor plus that joint's height over the sole);
* **low:** ``z_j(t) - r_role(j) < height_tol`` (4 cm);
* **slow:** ``|v_j(t)| < speed_tol`` (0.3 m/s) with the horizontal velocity from a centred
  difference, ``v_j(t) = (p_j(t+1) - p_j(t-1)) fps / 2`` (one-sided at the clip ends);
* **raw contact:** every joint of the foot is low and slow (a flat, still foot; a heel strike
  with the toe still up, or a toe-off with the heel already moving, is not contact);
* **filter:** gaps (non-contact runs strictly inside the clip) shorter than ``min_gap_s``
  (0.1 s) are filled, then contact runs shorter than ``min_contact_s`` (0.1 s) are removed:
  at least one frame either way, so a single-frame flicker never survives.

Speed and duration thresholds are in seconds and metres, so the result does not depend on the
frame rate.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from pipeline.clip import HumanClip

SIDES = ("left", "right")
HEIGHT_TOL = 0.04
SPEED_TOL = 0.3
FLOOR_PERCENTILE = 5.0
MIN_CONTACT_S = 0.1
MIN_GAP_S = 0.1


@dataclass(frozen=True)
class FootContacts:
    """Per-frame foot-ground contact flags: ``left``/``right`` (T,) bool.

    ``floor_height`` is the clip's planted-foot level (see the module doc), ``foot_joints``
    maps ``"left"``/``"right"`` to the joint names used, ankle first.
    """

    left: np.ndarray
    right: np.ndarray
    floor_height: float
    foot_joints: dict

    @property
    def both(self) -> np.ndarray:
        """(T, 2) bool, columns (left, right)."""
        return np.column_stack([self.left, self.right])

    @property
    def any(self) -> np.ndarray:
        """(T,) bool: some foot is down."""
        return self.left | self.right


def _side_of(name: str) -> str | None:
    low = name.lower()
    for side in SIDES:
        if (
            side in low
            or re.match(rf"^{side[0]}[_.\- ]", low)
            or re.match(rf"^{side[0].upper()}[A-Z]", name)
            or re.match(rf"^{side[0]}(foot|ankle|toe)", low)
        ):
            return side
    return None


def _role_of(name: str) -> tuple[str, int] | None:
    """(role, rank): role ``ankle`` or ``toe``; lower rank = preferred. ``None``: not a foot joint.

    ``*ankle*`` is the ankle; ``*toe*`` the toe; a bare ``*foot*`` is the toe joint in SMPL
    naming (which also has ``*ankle*``) and the ankle in BVH naming (which has ``*toe*``):
    :func:`find_foot_joints` settles that per side. End sites rank last.
    """
    low = name.lower()
    end = 1 if re.search(r"(_end|end_?site|_tip|nub)$", low) else 0
    if "ankle" in low:
        return "ankle", end
    if "toe" in low:
        return "toe", end
    if "foot" in low or "feet" in low:
        return "foot", end
    return None


def find_foot_joints(joint_names: tuple[str, ...] | list[str]) -> dict[str, tuple[str, ...]]:
    """``{"left": (ankle, toe), "right": (ankle, toe)}`` (one name when a side has only one).

    Raises ``ValueError`` listing the joints it saw when a side has no foot joint.
    """
    found: dict[str, tuple[str, ...]] = {}
    for side in SIDES:
        roles: dict[str, list[tuple[int, str]]] = {"ankle": [], "toe": [], "foot": []}
        for n in joint_names:
            role = _role_of(n)
            if role is not None and _side_of(n) == side:
                roles[role[0]].append((role[1], n))
        best = {r: min(c)[1] for r, c in roles.items() if c}
        ankle = best.get("ankle") or (best.get("foot") if "toe" in best else None)
        toe = best.get("toe") or (best.get("foot") if "ankle" in best else None)
        joints = tuple(dict.fromkeys(j for j in (ankle, toe, best.get("foot")) if j))[:2]
        if not joints:
            raise ValueError(f"no {side} foot joint (ankle/foot/toe) among the joints: {', '.join(joint_names)}")
        found[side] = joints
    return found


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[(start, stop)]`` of the True runs of a 1-D boolean array (``stop`` exclusive)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(mask).astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def label_runs(labels: np.ndarray) -> list[tuple[int, int, int]]:
    """``[(start, stop, label)]`` of the runs of equal labels ``>= 0`` of a 1-D int array (negative: no label;
    ``stop`` exclusive)."""
    labels = np.asarray(labels)
    if not len(labels):
        return []
    edges = (np.flatnonzero(np.diff(labels)) + 1).tolist()
    return [(a, b, int(labels[a])) for a, b in zip([0, *edges], [*edges, len(labels)]) if labels[a] >= 0]


def widen_runs(mask: np.ndarray, n: int) -> np.ndarray:
    """``mask`` (1-D bool) with each True run widened by ``n`` frames at both ends (clipped to the array)."""
    out = mask.copy()
    for a, b in runs(mask):
        out[max(0, a - n) : b + n] = True
    return out


def keep_runs(flags: np.ndarray, min_len: int, value: bool) -> np.ndarray:
    """``flags`` with runs of ``value`` shorter than ``min_len`` frames flipped.

    Runs of ``False`` touching either clip end are kept (a gap is only a gap between contacts).
    """
    out = flags.copy()
    T = len(flags)
    edges = np.flatnonzero(np.diff(flags.astype(np.int8))) + 1
    starts, ends = np.r_[0, edges], np.r_[edges, T]
    for a, b in zip(starts, ends):
        if flags[a] != value or b - a >= min_len:
            continue
        if not value and (a == 0 or b == T):
            continue
        out[a:b] = not value
    return out


def _horizontal_speed(xy: np.ndarray, fps: float) -> np.ndarray:
    """|d xy / dt| (T, J) by centred differences (one-sided at the ends)."""
    if xy.shape[0] < 2:
        return np.zeros(xy.shape[:2])
    return np.linalg.norm(np.gradient(xy, axis=0), axis=-1) * fps


def detect_foot_contacts(
    clip: HumanClip,
    *,
    height_tol: float = HEIGHT_TOL,
    speed_tol: float = SPEED_TOL,
    percentile: float = FLOOR_PERCENTILE,
    min_contact_s: float = MIN_CONTACT_S,
    min_gap_s: float = MIN_GAP_S,
) -> FootContacts:
    """Foot-ground contact flags of ``clip`` (see the module doc for the math)."""
    feet = find_foot_joints(clip.skeleton.joint_names)
    names = [n for side in SIDES for n in feet[side]]
    idx = [clip.skeleton.index(n) for n in names]
    pos = clip.joint_pos[:, idx]
    z = pos[..., 2]
    roles = [k for side in SIDES for k in range(len(feet[side]))]  # 0 ankle, 1 toe
    level = {r: np.percentile(z[:, [i for i, rr in enumerate(roles) if rr == r]], percentile) for r in set(roles)}
    low = z - np.array([level[r] for r in roles]) < height_tol
    slow = _horizontal_speed(pos[..., :2], clip.fps) < speed_tol
    planted = low & slow
    min_run = max(2, int(round(min_contact_s * clip.fps)))
    min_gap = max(2, int(round(min_gap_s * clip.fps)))
    out, k = {}, 0
    for side in SIDES:
        n = len(feet[side])
        raw = planted[:, k : k + n].all(axis=1)
        k += n
        out[side] = keep_runs(keep_runs(raw, min_gap, False), min_run, True)
    floor = float(np.percentile(z.min(axis=1), percentile))
    return FootContacts(out["left"], out["right"], floor, {s: feet[s] for s in SIDES})
