"""The four demonstrations: PickUp, SitStand, Push, Carry (timings in the package docstring).

Each is built from a *segment* (:data:`SEGMENTS`): the task's motion from the walker standing at its approach
stance on, in the task's local :class:`Frame` (the single demonstration's start stance: origin, facing +x). A
single demonstration is the identity frame, 0.3 s standing and a straight walk to that stance; a composed one
(:mod:`ingest.synthetic.compose`) places frames in the world and walks between them. The identity frame maps
every local point and heading onto itself exactly, so the single demonstrations are the same arrays bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from ingest.synthetic.body import HAND_OFFSET, Body, Channels, evaluate, grip_points, make_demo, yaw_pose
from ingest.synthetic.gait import GaitPlan, Keys, heading
from ingest.synthetic.skeleton import PELVIS_FWD
from pipeline.geometry import Chair, Primitive

SMALL_BOX = Primitive("box", (0.20, 0.15, 0.15))  # 0.4 x 0.3 x 0.3 m, long axis along the walker
LARGE_BOX = Primitive("box", (0.30, 0.30, 0.60))  # 0.6 x 0.6 x 1.2 m cabinet-like box
# Seat top 0.40 m, the G1's chair: the paper's SitStand success asks for the root in [0.3, 0.6] m while seated.
# Measured (8 synthetic SitStand seeds each, physicalize + the QP teacher in the Train I evaluation at scale 1.0):
# seat 0.45 m -> root seated at 0.64 m, teacher success 0% (23 of 25 clips valid); 0.40 m -> 0.56 m, 100% (7 of 8
# valid); 0.36 m -> 0.51 m, 100%, but 2 of 8 valid (standing up from it falls).
CHAIR = Chair(seat_height=0.40)
SMALL_BOX_MASS, LARGE_BOX_MASS, CHAIR_MASS = 1.5, 20.0, 6.0
# The lifted box is as heavy as the G1 can lift it this way: the static torque the lift asks of the
# waist pitch motor (50 N m; physicalize.static_torque, the grasp's loads) is 0.87 / 0.93 / 1.00 / 1.07 / 1.14
# of its limit at 1 / 1.5 / 2 / 2.5 / 3 kg, and the physicalized PickUp held the box up to 1.5 kg and
# lost it in the lift from 2 kg on.
# The pushed box stands on furniture sliders (its floor friction; the hands keep the default friction): pushed at
# 1.10 m it slides at mu m g = 29 N; it tips about its far bottom edge at m g (0.30 m) / (1.10 m) = 54 N (with a
# floor friction of 0.8 it would tip long before sliding at 157 N, which makes the demonstration physically
# impossible).
LARGE_BOX_FLOOR_FRICTION = 0.15
OBJECT_NAME = "object"  # one name in every clip: a dataset has one feature spec (geometry is per clip)

# Lifting from the floor: the box centre this far ahead of the ankles' midpoint; squat posture.
REACH = 0.47
SQUAT = dict(z=0.45, dx=-0.18, pp=0.60, sp=0.50)
HOLD_FWD, HOLD_Z = 0.30, 0.95  # held box centre ahead of the pelvis and above the floor
# Wrist targets in the box frame: on the side faces (+-y), a little towards the walker and up.
SMALL_GRIP = np.array([[-0.08, 0.15 + HAND_OFFSET, 0.12], [-0.08, -0.15 - HAND_OFFSET, 0.12]])
LARGE_GRIP = np.array([[-0.30 - HAND_OFFSET, 0.18, 0.50], [-0.30 - HAND_OFFSET, -0.18, 0.50]])
PUSH_STAND = 0.55  # ankle midpoint behind the large box's near face while pushing
SEAT_CLEARANCE = 0.13  # seated pelvis joint above the seat top (hip joints ~4.5 cm above it)
HOLD_S = 3.0  # PickUp holds the box this long


@dataclass(frozen=True)
class Frame:
    """A task's local frame in the world: local ``(x, y)`` is at ``origin + R(yaw) (x, y)``, local heading ``a``
    is ``yaw + a``. The identity frame (the default) maps every value onto itself exactly."""

    origin: tuple[float, float] = (0.0, 0.0)
    yaw: float = 0.0

    def point(self, x, y) -> np.ndarray:
        """World xy of local ``(x, y)`` (scalars: (2,); arrays of N: (N, 2))."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.stack([self.origin[0] + (x * c - y * s), self.origin[1] + (x * s + y * c)], axis=-1)

    def along(self, v: np.ndarray) -> np.ndarray:
        """(N,) the component of world vectors ``v`` (N, 2) along the frame's +x."""
        return v[:, 0] * np.cos(self.yaw) + v[:, 1] * np.sin(self.yaw)


Finish = Callable[[Body], tuple[dict, np.ndarray, dict]]


@dataclass(frozen=True)
class Part:
    """A task segment added to a shared gait plan and channels: its phases ``(name, start, end)``, its end time
    (the walker standing still), ``finish(body)`` -> (its object's dict for :func:`make_demo`, wrist targets
    (T, 2, 3), joint name -> (T,) contact flags) once the body is evaluated on the clip's time grid, and ``rest``:
    its object's world xy before and after the segment (a box still held at the end: where it was lifted from)."""

    phases: list[tuple[str, float, float]]
    end: float
    finish: Finish
    rest: tuple[np.ndarray, np.ndarray]  # the object's world xy at rest before and after the segment


@dataclass(frozen=True)
class Segment:
    """A task as a segment: ``draw(rng)`` its object's local parameters (the seed's jitter), ``stance(params)``
    the local approach stance (ankle midpoint, facing local +x), ``build(t, g, ch, frame, params, **options)``
    the :class:`Part` from the walker standing at that stance at ``t``."""

    draw: Callable[[np.random.Generator], object]
    stance: Callable[[object], np.ndarray]
    build: Callable[..., Part]


def time_grid(t_end: float, fps: float) -> np.ndarray:
    return np.arange(int(round(t_end * fps)) + 1) / fps


def _approach(out_dirs, hw: np.ndarray, out: float = 0.08, up: float = 0.05) -> np.ndarray:
    """Extra wrist offset while the hands close in or leave (weight < 1): from outside, above."""
    return (1.0 - hw)[:, None, None] * (np.asarray(out_dirs) * out + np.array([0.0, 0.0, up]))


def _draw_box(carry: bool) -> Callable[[np.random.Generator], np.ndarray]:
    def draw(rng) -> np.ndarray:  # local box centre: 1.97 m (PickUp) or 0.97 m (Carry) ahead, +-4 / +-5 cm
        return np.array([REACH + (0.50 if carry else 1.50) + rng.uniform(-0.04, 0.04), rng.uniform(-0.05, 0.05)])

    return draw


def _put_down(t1: float, g: GaitPlan, ch: Channels, lam_xy: Keys, lam_z: Keys, phases: list) -> tuple[float, tuple]:
    """Squat and set the held box down ``REACH`` ahead (1.0 s), settle 0.2 s, release 0.6 s, rise 1.0 s (from
    0.2 s into the release), stand 0.2 s. Returns (end time, (t1, box xy, box yaw))."""
    yaw1 = g.yaw
    box1 = g.centre + REACH * heading(yaw1)
    ch.to(t1, t1 + 1.0, z=SQUAT["z"], dx=SQUAT["dx"], pp=SQUAT["pp"], sp=SQUAT["sp"])
    lam_xy.set(t1, 1.0).set(t1 + 0.6, 0.0)
    lam_z.set(t1 + 0.15, 1.0).set(t1 + 1.0, 0.0)
    t_rel = t1 + 1.2
    ch.to(t_rel, t_rel + 0.6, hw=0.0)
    ch.to(t_rel + 0.2, t_rel + 1.2, z=0.93, dx=0.0, pp=0.0, sp=0.0)
    t_end = t_rel + 1.4
    phases += [
        ("put_down", t1, t1 + 1.0),
        ("settle", t1 + 1.0, t_rel),
        ("release", t_rel, t_rel + 0.6),
        ("rise", t_rel + 0.2, t_rel + 1.2),
        ("stand", t_rel + 1.2, t_end),
    ]
    return t_end, (t1, box1, yaw1)


def lift_part(
    t: float, g: GaitPlan, ch: Channels, frame: Frame, box0: np.ndarray, *, carry: bool, hold=HOLD_S, put_back=False
) -> Part:
    """Squat and reach 1.0 s (hands in from 0.3 s), grasp 0.25 s, lift 1.0 s to the waist; then hold ``hold``
    seconds (PickUp) or carry it along :func:`_carry_path` (Carry); Carry, or PickUp with ``put_back``, then sets
    it down (:func:`_put_down`). ``box0``: the box's local centre, the walker ``REACH`` behind it."""
    ch.to(t, t + 1.0, z=SQUAT["z"], dx=SQUAT["dx"], pp=SQUAT["pp"], sp=SQUAT["sp"])
    ch.to(t + 0.3, t + 1.0, hw=1.0)
    t_grip, t_lift = t + 1.0, t + 1.25
    ch.to(t_lift, t_lift + 1.0, z=0.93, dx=0.0, pp=0.0, sp=-0.05)
    # box blend floor -> held: up first, then in towards the body (clear of the knees)
    lam_z = Keys(0.0, 0.0).set(t_lift, 0.0).set(t_lift + 0.85, 1.0)
    lam_xy = Keys(0.0, 0.0).set(t_lift + 0.4, 0.0).set(t_lift + 1.0, 1.0)
    phases = [("squat_reach", t, t_grip), ("grasp", t_grip, t_lift), ("lift", t_lift, t_lift + 1.0)]
    t = t_lift + 1.0
    if carry:
        t1 = g.walk(t, _carry_path(g.centre, g.yaw), period=0.55, swing=0.42, clearance=0.06)
        phases.append(("carry", t, t1))
    else:
        t1 = t + hold
        phases.append(("hold", t, t1))
    t_end, put = _put_down(t1, g, ch, lam_xy, lam_z, phases) if carry or put_back else (t1, None)

    def finish(body: Body) -> tuple[dict, np.ndarray, dict]:
        ts = body.t
        hold = np.column_stack([body.centre + HOLD_FWD * body.fwd, np.full(len(ts), HOLD_Z)])
        floor = np.tile([*frame.point(*box0), SMALL_BOX.size[2]], (len(ts), 1))
        floor_yaw = np.full(len(ts), frame.yaw)
        if put is not None:  # from the put-down on, the floor pose is the carry's target
            later = ts >= put[0]
            floor[later, :2], floor_yaw[later] = put[1], put[2]
        la = np.column_stack([lam_xy(ts), lam_xy(ts), lam_z(ts)])
        yaw = (1 - la[:, 0]) * floor_yaw + la[:, 0] * body.yaw
        pose = yaw_pose((1 - la) * floor + la * hold, yaw)
        hw = body.ch["hw"]
        left = np.column_stack([-np.sin(yaw), np.cos(yaw), np.zeros(len(ts))])
        target = grip_points(pose, SMALL_GRIP) + _approach(np.stack([left, -left], 1), hw)
        touch = hw >= 1.0
        obj = dict(name=OBJECT_NAME, geometry=SMALL_BOX, pose=pose, contact=touch, mass=SMALL_BOX_MASS)
        return obj, target, {"left_wrist": touch, "right_wrist": touch}

    start = frame.point(*box0)
    return Part(phases, t_end, finish, (start, start if put is None else put[1]))


def _carry_path(c0: np.ndarray, yaw0: float = 0.0) -> list[tuple]:
    """Stances along 0.9 m straight, a 90 degree left arc of radius 0.5 m, then 0.4 m straight, from the stance
    ``(c0, yaw0)``."""
    r, a, b = 0.5, 0.9, 0.4
    length = a + r * np.pi / 2 + b
    n = int(np.ceil(length / 0.55))
    start = Frame((float(c0[0]), float(c0[1])), yaw0)
    out = []
    for s in np.linspace(0, length, n + 1)[1:]:
        if s <= a:
            p, yaw = (s, 0.0), 0.0
        elif s <= a + r * np.pi / 2:
            phi = (s - a) / r
            p, yaw = (a + r * np.sin(phi), r * (1 - np.cos(phi))), phi
        else:
            p, yaw = (a + r, r + s - a - r * np.pi / 2), np.pi / 2
        out.append((start.point(*p), yaw0 + yaw))
    return out


def sit_part(t: float, g: GaitPlan, ch: Channels, frame: Frame, cx: float) -> Part:
    """Turn 180 deg left in place (4 steps of 45 deg + closing, 0.17 m back towards the chair), sit down 1.3 s,
    seated 1.4 s (hands on the thighs), stand up 1.3 s, stand 0.3 s. ``cx``: the chair's local x."""
    feet_x = cx - 0.45  # ankles in front of the seat once turned round
    turn = [(frame.point(cx - 0.62 + 0.17 * k / 4, 0.0), frame.yaw + np.pi * k / 4) for k in range(1, 5)]
    t1 = g.walk(t, turn, period=0.55, swing=0.4, clearance=0.05, first=0)
    phases = [("turn", t, t1)]
    seat = np.array([cx + 0.03, 0.0, CHAIR.seat_height + SEAT_CLEARANCE])
    dx = -(seat[0] - feet_x) - PELVIS_FWD  # pelvis shift along the heading (-x) onto the seat
    t = t1
    ch.to(t, t + 0.6, pp=0.35, sp=0.35).to(t + 0.6, t + 1.3, pp=-0.05, sp=0.0)
    ch.to(t, t + 1.0, dx=dx).to(t + 0.15, t + 1.3, z=seat[2]).to(t + 0.6, t + 1.3, hw=1.0)
    t_sit = t + 1.3
    t_up = t_sit + 1.4
    ch.to(t_up, t_up + 0.5, pp=0.35, sp=0.4).to(t_up + 0.5, t_up + 1.3, pp=0.0, sp=0.0)
    ch.to(t_up, t_up + 0.5, hw=0.0).to(t_up + 0.1, t_up + 1.1, dx=0.0).to(t_up + 0.3, t_up + 1.3, z=0.93)
    t_end = t_up + 1.6
    phases += [
        ("sit_down", t, t_sit),
        ("seated", t_sit, t_up),
        ("stand_up", t_up, t_up + 1.3),
        ("stand", t_up + 1.3, t_end),
    ]

    def finish(body: Body) -> tuple[dict, np.ndarray, dict]:
        ts = body.t
        # while seated the hands rest on the thighs (no object contact)
        side = np.stack([-np.sin(body.yaw), np.cos(body.yaw)], -1)
        thigh = body.pelvis[:, :2] + 0.24 * body.fwd
        target = np.stack(
            [
                np.column_stack([thigh + 0.13 * side, body.pelvis[:, 2] + 0.04]),
                np.column_stack([thigh - 0.13 * side, body.pelvis[:, 2] + 0.04]),
            ],
            1,
        )
        seated = (ts >= t_sit - 1e-9) & (ts <= t_up + 1e-9)
        chair = dict(
            name=OBJECT_NAME,
            geometry=CHAIR,
            pose=yaw_pose(np.tile([*frame.point(cx, 0.0), 0.0], (len(ts), 1)), frame.yaw + np.pi),
            contact=seated,
            mass=CHAIR_MASS,
        )
        return chair, target, {"pelvis": seated, "left_hip": seated, "right_hip": seated}

    return Part(phases, t_end, finish, (frame.point(cx, 0.0), frame.point(cx, 0.0)))


def push_part(t: float, g: GaitPlan, ch: Channels, frame: Frame, bx: float) -> Part:
    """Reach 0.7 s (hands on the near face at 1.10 m), brace 0.1 s, push 1.0 m in short steps (0.34 m, 0.6 s),
    release 0.6 s, step back 0.3 m (from 0.5 s into the release), stand 0.3 s. ``bx``: the box's local x."""
    face = bx - LARGE_BOX.size[0]
    ch.to(t, t + 0.7, hw=1.0, pp=0.10, sp=0.10)
    t_push = t + 0.8
    t1 = g.walk_straight(
        t_push, frame.point(face - PUSH_STAND + 1.0, 0.0), max_step=0.34, period=0.6, swing=0.45, clearance=0.05
    )
    ch.to(t1, t1 + 0.6, hw=0.0, pp=0.0, sp=0.0)
    t2 = g.walk_straight(t1 + 0.5, frame.point(face - PUSH_STAND + 0.7, 0.0), period=0.6, swing=0.42, clearance=0.04)
    t_end = t2 + 0.3
    phases = [
        ("reach", t, t + 0.7),
        ("brace", t + 0.7, t_push),
        ("push", t_push, t1),
        ("release", t1, t1 + 0.6),
        ("step_back", t1 + 0.5, t2),
        ("stand", t2, t_end),
    ]

    def finish(body: Body) -> tuple[dict, np.ndarray, dict]:
        ts = body.t
        i0 = np.searchsorted(ts, t_push)
        shift = np.clip(frame.along(body.centre - body.centre[i0]), 0.0, None)
        shift[ts < t_push] = 0.0
        shift[ts > t1] = shift[ts <= t1][-1]
        xy = frame.point(bx + shift, np.zeros(len(ts)))
        pose = yaw_pose(np.column_stack([xy, np.full(len(ts), LARGE_BOX.size[2])]), frame.yaw)
        hw = body.ch["hw"]
        back = [[-np.cos(frame.yaw), -np.sin(frame.yaw), 0.0]] * 2
        target = grip_points(pose, LARGE_GRIP) + _approach(back, hw, out=0.08, up=0.0)
        touch = hw >= 1.0
        obj = dict(
            name=OBJECT_NAME,
            geometry=LARGE_BOX,
            pose=pose,
            contact=touch,
            mass=LARGE_BOX_MASS,
            floor_friction=LARGE_BOX_FLOOR_FRICTION,
        )
        return obj, target, {"left_wrist": touch, "right_wrist": touch}

    return Part(phases, t_end, finish, (frame.point(bx, 0.0), frame.point(bx + 1.0, 0.0)))  # pushed 1.0 m


def _box_stance(box0: np.ndarray) -> np.ndarray:
    return box0 - [REACH, 0.0]


SEGMENTS: dict[str, Segment] = {
    "PickUp": Segment(_draw_box(carry=False), _box_stance, partial(lift_part, carry=False)),
    "SitStand": Segment(lambda rng: 1.65 + rng.uniform(-0.05, 0.05), lambda cx: np.array([cx - 0.62, 0.0]), sit_part),
    "Push": Segment(
        lambda rng: 2.2 + rng.uniform(-0.05, 0.05),
        lambda bx: np.array([bx - LARGE_BOX.size[0] - PUSH_STAND, 0.0]),
        push_part,
    ),
    "Carry": Segment(_draw_box(carry=True), _box_stance, partial(lift_part, carry=True)),
}


def single(task: str, rng, fps: float):
    """The single demonstration of ``task``: stand 0.3 s at the origin facing +x, walk straight to the approach
    stance, then the task's segment (:data:`SEGMENTS`)."""
    seg, frame = SEGMENTS[task], Frame()
    params = seg.draw(rng)
    g = GaitPlan((0.0, 0.0), 0.0)
    ch = Channels()
    t = g.walk_straight(0.3, frame.point(*seg.stance(params)))
    part = seg.build(t, g, ch, frame, params)
    body = evaluate(time_grid(part.end, fps), g, ch)
    obj, target, contacts = part.finish(body)
    phases = [("stand", 0.0, 0.3), ("approach", 0.3, t), *part.phases]
    return make_demo(task, fps, body, target, [obj], phases, contacts)


def pickup(rng, fps: float):
    return single("PickUp", rng, fps)


def carry(rng, fps: float):
    return single("Carry", rng, fps)


def sit_stand(rng, fps: float):
    return single("SitStand", rng, fps)


def push(rng, fps: float):
    return single("Push", rng, fps)
