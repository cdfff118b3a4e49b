"""Where a rollout loses its object: the figures an object's loss is traced by, carried by every physicalized clip with
objects beside its validity figures (:mod:`physicalize.validate`) and balance trace (:mod:`physicalize.balance`). Not
bars: causes.

At the object's drift onset -- the first frame an object is :data:`OBJECT_DRIFT_M` off its reference track (where the
search starts, :mod:`physicalize.search.beam`; the loss bar itself is :data:`physicalize.validate.OBJECT_LOST_M`):

* ``object_drift_s`` (None: it never strayed; then no other figure) and ``object_drift_object``;
* ``object_drift_along_m`` / ``object_drift_lateral_m`` -- its horizontal error along and across the reference's
  direction of motion over the :data:`WINDOW_S` around it (negative along: behind its track; None where the
  reference barely moves), ``object_drift_rise_m`` its height error;
* ``object_drift_yaw_deg`` -- its heading error;
* ``object_drift_hands_planned`` -- the hands the grasp schedule holds it with then (:mod:`physicalize.grasp`);
* ``object_drift_hands_touching`` -- the hands measured touching it in the :data:`WINDOW_S` before;
* ``object_drift_cause`` -- the largest error, named: ``turned`` (the heading off by :data:`TURNED_DEG` or more),
  ``dropped`` (:data:`DROPPED_M` below its track), else ``left behind``, ``ran ahead`` or ``pushed sideways``.

Why: on the shared slides the object strays while the robot still stands, and before the fall the balance trace
reads; a box pushed by one hand, or by two of which one has lost its face, turns (``sub8_plasticbox_002``: +12 deg
0.2 s after the push starts, one hand holding).
"""

from __future__ import annotations

import numpy as np

from physicalize.reference import Reference
from physicalize.rollout import Rollout
from pipeline.rotations import yaw_of

OBJECT_DRIFT_M = 0.1
WINDOW_S = 0.2
TURNED_DEG = 10.0
DROPPED_M = 0.05
MOVING_M = 0.01  # the reference moves less than this over the window: no direction of motion


def hand_columns(contact_links: tuple[str, ...]) -> tuple[list[int], list[int]]:
    """The columns of a rollout's ``contact`` that are the left and the right hand's links (wrist, hand)."""
    hands = [i for i, name in enumerate(contact_links) if "wrist" in name or "hand" in name]
    return [i for i in hands if contact_links[i].startswith("left")], [
        i for i in hands if contact_links[i].startswith("right")
    ]


def object_trace_figures(
    ref: Reference,
    roll: Rollout,
    qpos_adr: dict[str, int],
    tracks: dict[str, np.ndarray],
    contact_links: tuple[str, ...],
) -> dict:
    """The module docstring's figures of ``roll``: the objects at their ``qpos_adr`` and their reference ``tracks``
    ({name: (T, 7)}); the hands among the rollout's ``contact_links``."""
    T, fps = roll.frames, ref.fps
    objects = {n: (qpos_adr[n], np.asarray(tracks[n])) for n in tracks if n in qpos_adr}
    onset, name = T, None
    for n, (adr, track) in objects.items():
        far = np.flatnonzero(np.linalg.norm(roll.qpos[:, adr : adr + 3] - track[:T, :3], axis=1) > OBJECT_DRIFT_M)
        if far.size and far[0] < onset:
            onset, name = int(far[0]), n
    if name is None:
        return {"object_drift_s": None} if objects else {}
    adr, track = objects[name]
    err = roll.qpos[onset, adr : adr + 3] - track[onset, :3]
    w = max(int(round(WINDOW_S * fps)), 1)
    motion = track[min(onset + w, len(track) - 1), :2] - track[max(onset - w, 0), :2]
    moving = float(np.linalg.norm(motion)) >= MOVING_M
    u = motion / np.linalg.norm(motion) if moving else np.zeros(2)
    along, lateral = float(err[:2] @ u), float(err[:2] @ np.array([-u[1], u[0]]))
    yaw = float(
        np.degrees(
            (yaw_of(roll.qpos[onset, adr + 3 : adr + 7]) - yaw_of(track[onset, 3:7]) + np.pi) % (2 * np.pi) - np.pi
        )
    )
    planned = 0 if ref.grasp is None else int(ref.grasp.grasped[min(onset, ref.frames - 1)].sum())
    left, right = hand_columns(contact_links)
    recent = roll.contact[max(onset - w, 0) : onset + 1] if roll.contact.size else np.zeros((0, 0), bool)
    touching = sum(bool(cols) and bool(recent[:, cols].any()) for cols in (left, right)) if recent.size else 0
    if abs(yaw) >= TURNED_DEG:
        cause = "turned"
    elif err[2] <= -DROPPED_M:
        cause = "dropped"
    elif moving and abs(along) >= abs(lateral):
        cause = "left behind" if along < 0 else "ran ahead"
    else:
        cause = "pushed sideways"
    return {
        "object_drift_s": onset / fps,
        "object_drift_object": name,
        "object_drift_along_m": along if moving else None,
        "object_drift_lateral_m": lateral if moving else None,
        "object_drift_rise_m": float(err[2]),
        "object_drift_yaw_deg": yaw,
        "object_drift_hands_planned": planned,
        "object_drift_hands_touching": touching,
        "object_drift_cause": cause,
    }
