"""SYNTHETIC human-object demonstrations: the toolkit's embedded default input.

:func:`default_clips` returns four clips generated here (no motion capture involved), each
labelled ``synthetic=True``, ``source="synthetic:<task>"``, in the :class:`~pipeline.clip.HumanClip`
schema on the SMPL body's 22 joints (:mod:`ingest.synthetic.skeleton`, a 1.70 m adult; z-up,
metres, wxyz; the walker starts at the origin facing +x).

How they are made: per-frame targets (pelvis path and heading, trunk pitch, flat-foot ankle
targets from a footstep plan, wrist targets on the object) are turned into joint rotations by
2-link IK for legs and arms, and positions by forward kinematics, so bone lengths are exactly
constant and ``joint_quat`` holds the global joint orientations (identity = the T-pose rest,
facing +x). Standing: pelvis 0.92 m, shoulders 1.385 m, hanging wrists 0.84 m. Walking
(:mod:`ingest.synthetic.gait`): step length <= 0.55 m (0.33 m pushing), step period 0.5 s
(cadence 2.0 steps/s, stride frequency 1.0 Hz; 0.55 s turning or carrying, 0.6 s pushing),
swing 0.4 s, ~1.05 m/s at cruise with smooth starts and stops; planted feet flat and
motionless, 5-7 cm swing clearance, pelvis bob ~4 cm and sway +-2 cm, arms swinging against
the legs. Squats keep the feet planted (leg IK) while the pelvis drops to 0.45 m and the trunk
bends ~60 deg. Every transition is minimum-jerk. A held box moves rigidly with the wrists; it
rests exactly on the floor (z = half height, yaw-only orientation) otherwise.

Contacts: ``HumanClip.contacts[t, j]`` is True when joint ``j`` touches an *object* (the wrists
on a box; pelvis and hips on the chair seat), never the floor: foot-ground contact is derived
downstream from foot heights and speeds (:attr:`SyntheticDemo.foot_stance` has the generator's
own flags). A touching wrist joint sits ``HAND_OFFSET`` = 4 cm outside the touched face (half a
hand's thickness plus the palm); ``ObjectTrack.contact`` is True while both hands touch.

Tasks and phases (seconds; the seed only moves the objects by a few cm, so the timings hold
for every seed to within a frame; exact values in :attr:`SyntheticDemo.phases`; consecutive
phases may overlap, never leave gaps):

* **PickUp** (7.9 s; box 0.4 x 0.3 x 0.3 m, 1.5 kg, ~1.97 m ahead): stand 0-0.3, approach 0.3-2.6
  (1.5 m, 3 steps + closing step), squat_reach 2.6-3.6 (pelvis 0.92 -> 0.45 m, trunk ~60 deg,
  hands reach the side faces), grasp 3.6-3.85, lift 3.85-4.85 (box to waist, centre 0.95 m),
  hold 4.85-7.85 (held 3 s).
* **SitStand** (9.4 s; chair, seat 0.45 m, facing the walker): stand 0-0.3, approach 0.3-2.1,
  turn 2.1-5.1 (180 deg in place, 4 steps of 45 deg + closing), sit_down 5.1-6.4 (trunk
  flexes ~40 deg, pelvis back 0.5 m onto the seat, down to seat + 0.13 m), seated 6.4-7.8
  (hands on thighs), stand_up 7.8-9.1, stand 9.1-9.4.
* **Push** (8.3 s; box 0.6 x 0.6 x 1.2 m, 20 kg on sliders: floor friction 0.15): stand 0-0.3, approach
  0.3-2.6, reach 2.6-3.3 (hands on the near face at 1.10 m), brace 3.3-3.4, push 3.4-6.05 (1.0 m at ~0.45 m/s,
  the box slides with the hands), release 6.05-6.65, step_back 6.55-7.95 (0.3 m), stand.
* **Carry** (9.5 s; the PickUp box, ~0.97 m ahead): stand 0-0.3, approach 0.3-1.6, squat_reach
  1.6-2.6, grasp 2.6-2.85, lift 2.85-3.85, carry 3.85-6.9 (2.1 m: 0.9 m straight, a 90 deg
  left arc of radius 0.5 m, 0.4 m), put_down 6.9-7.9, settle 7.9-8.1, release 8.1-8.7,
  rise 8.3-9.3, stand. The box ends ~1.65 m from where it started.

Composed long-horizon demonstrations (:mod:`ingest.synthetic.compose`, task ``"Chain"``): :func:`composed` strings
the tasks' segments (the same motions, :data:`~ingest.synthetic.tasks.SEGMENTS`) with the walking between them in
one clip with one object per segment (``object``, ``object_2``, ...), e.g. Carry, SitStand, Push (~30 s);
:func:`chain_demo` is a corpus seed's (:data:`CHAIN_ORDERS`: every ordered pair of two tasks). They are not part of
:func:`default_demos`.
"""

from __future__ import annotations

import numpy as np

from ingest.synthetic.body import HAND_OFFSET, Phase, SyntheticDemo
from ingest.synthetic.compose import CHAIN, CHAIN_ORDERS, chain_demo, composed
from ingest.synthetic.skeleton import JOINT_NAMES, PARENTS, SKELETON, SUBJECT_HEIGHT
from ingest.synthetic.skeleton import OFFSETS as REST_OFFSETS
from ingest.synthetic.tasks import carry, pickup, push, sit_stand
from pipeline.clip import HumanClip

TASKS = {"PickUp": pickup, "SitStand": sit_stand, "Push": push, "Carry": carry}


def default_demos(fps: float = 30.0, seed: int = 0) -> list[SyntheticDemo]:
    """The four demonstrations (PickUp, SitStand, Push, Carry) with their phases and foot
    stance flags; the same ``fps`` and ``seed`` give bit-identical arrays."""
    return [make(np.random.default_rng([seed, i]), float(fps)) for i, make in enumerate(TASKS.values())]


def default_clips(fps: float = 30.0, seed: int = 0) -> list[HumanClip]:
    """The four synthetic clips (see the module docstring)."""
    return [d.clip for d in default_demos(fps, seed)]


__all__ = [
    "CHAIN",
    "CHAIN_ORDERS",
    "HAND_OFFSET",
    "JOINT_NAMES",
    "PARENTS",
    "REST_OFFSETS",
    "SKELETON",
    "SUBJECT_HEIGHT",
    "TASKS",
    "Phase",
    "SyntheticDemo",
    "chain_demo",
    "composed",
    "default_clips",
    "default_demos",
]
