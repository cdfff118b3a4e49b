"""The grasp planner's parameters (:class:`GraspConfig`, used by :mod:`physicalize.grasp` and
:mod:`physicalize.grasp_force`)."""

from __future__ import annotations

from dataclasses import dataclass


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
    slide_speed: float = 0.05  # m/s: a sliding object's floor friction is ramped in up to this reference speed
    push_travel: float = 0.10  # m: a one-hand contact holds only an object the reference slides this far (a push)
    max_hand_force: float = 120.0  # N: cap on the force one hand applies
    clearance: float = 0.05  # m: an unlabelled hand's surface is kept this far from objects
    # ... except this many frames before and after its labelled contacts (reaching, letting go)
    approach_frames: int = 25
    w_clear: float = 50.0  # hand task weight while it is kept off an object
    # share of a lifted object's weight the hands carry when they hold it from one side (not squeezed between them)
    side_lift: float = 0.5
    # m: a two-hand grip's axis is moved onto the vertical through the object's centre of mass, this high above it
    # (None: where the reference hands are)
    grip_above: float | None = 0.03
