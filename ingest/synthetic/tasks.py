"""The four demonstrations: PickUp, SitStand, Push, Carry (timings in the package docstring)."""

from __future__ import annotations

import numpy as np

from ingest.synthetic.body import HAND_OFFSET, Channels, evaluate, grip_points, make_demo, yaw_pose
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


def _time_grid(t_end: float, fps: float) -> np.ndarray:
    return np.arange(int(round(t_end * fps)) + 1) / fps


def _approach(out_dirs, hw: np.ndarray, out: float = 0.08, up: float = 0.05) -> np.ndarray:
    """Extra wrist offset while the hands close in or leave (weight < 1): from outside, above."""
    return (1.0 - hw)[:, None, None] * (np.asarray(out_dirs) * out + np.array([0.0, 0.0, up]))


def _lift_box(rng, fps: float, task: str, carry: bool):
    g = GaitPlan((0.0, 0.0), 0.0)
    ch = Channels()
    box0 = np.array([REACH + (0.50 if carry else 1.50) + rng.uniform(-0.04, 0.04), rng.uniform(-0.05, 0.05)])
    phases = [("stand", 0.0, 0.3)]
    t = g.walk_straight(0.3, box0 - [REACH, 0.0])
    phases.append(("approach", 0.3, t))
    # squat and reach (hands arrive at t + 1.0), grip, lift (1.0 s)
    ch.to(t, t + 1.0, z=SQUAT["z"], dx=SQUAT["dx"], pp=SQUAT["pp"], sp=SQUAT["sp"])
    ch.to(t + 0.3, t + 1.0, hw=1.0)
    t_grip, t_lift = t + 1.0, t + 1.25
    ch.to(t_lift, t_lift + 1.0, z=0.93, dx=0.0, pp=0.0, sp=-0.05)
    # box blend floor -> held: up first, then in towards the body (clear of the knees)
    lam_z = Keys(0.0, 0.0).set(t_lift, 0.0).set(t_lift + 0.85, 1.0)
    lam_xy = Keys(0.0, 0.0).set(t_lift + 0.4, 0.0).set(t_lift + 1.0, 1.0)
    phases += [("squat_reach", t, t_grip), ("grasp", t_grip, t_lift), ("lift", t_lift, t_lift + 1.0)]
    t = t_lift + 1.0
    if not carry:
        phases.append(("hold", t, t + 3.0))
        t_end, put = t + 3.0, None
    else:
        t1 = g.walk(t, _carry_path(g.centre), period=0.55, swing=0.42, clearance=0.06)
        phases.append(("carry", t, t1))
        yaw1 = g.yaw
        box1 = g.centre + REACH * heading(yaw1)
        ch.to(t1, t1 + 1.0, z=SQUAT["z"], dx=SQUAT["dx"], pp=SQUAT["pp"], sp=SQUAT["sp"])
        lam_xy.set(t1, 1.0).set(t1 + 0.6, 0.0)
        lam_z.set(t1 + 0.15, 1.0).set(t1 + 1.0, 0.0)
        t_rel = t1 + 1.2
        ch.to(t_rel, t_rel + 0.6, hw=0.0)
        ch.to(t_rel + 0.2, t_rel + 1.2, z=0.93, dx=0.0, pp=0.0, sp=0.0)
        phases += [
            ("put_down", t1, t1 + 1.0),
            ("settle", t1 + 1.0, t_rel),
            ("release", t_rel, t_rel + 0.6),
            ("rise", t_rel + 0.2, t_rel + 1.2),
        ]
        t_end, put = t_rel + 1.4, (t1, box1, yaw1)
        phases.append(("stand", t_rel + 1.2, t_end))
    ts = _time_grid(t_end, fps)
    body = evaluate(ts, g, ch)
    hold = np.column_stack([body.centre + HOLD_FWD * body.fwd, np.full(len(ts), HOLD_Z)])
    floor = np.tile([*box0, SMALL_BOX.size[2]], (len(ts), 1))
    floor_yaw = np.zeros(len(ts))
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
    return make_demo(task, fps, body, target, [obj], phases, {"left_wrist": touch, "right_wrist": touch})


def _carry_path(c0: np.ndarray) -> list[tuple]:
    """Stances along 0.9 m straight, a 90 degree left arc of radius 0.5 m, then 0.4 m straight."""
    r, a, b = 0.5, 0.9, 0.4
    length = a + r * np.pi / 2 + b
    n = int(np.ceil(length / 0.55))
    out = []
    for s in np.linspace(0, length, n + 1)[1:]:
        if s <= a:
            p, yaw = c0 + [s, 0.0], 0.0
        elif s <= a + r * np.pi / 2:
            phi = (s - a) / r
            p, yaw = c0 + [a + r * np.sin(phi), r * (1 - np.cos(phi))], phi
        else:
            p, yaw = c0 + [a + r, r + s - a - r * np.pi / 2], np.pi / 2
        out.append((p, yaw))
    return out


def pickup(rng, fps: float):
    return _lift_box(rng, fps, "PickUp", carry=False)


def carry(rng, fps: float):
    return _lift_box(rng, fps, "Carry", carry=True)


def sit_stand(rng, fps: float):
    cx = 1.65 + rng.uniform(-0.05, 0.05)
    g = GaitPlan((0.0, 0.0), 0.0)
    ch = Channels()
    feet_x = cx - 0.45  # ankles in front of the seat once turned round
    t = g.walk_straight(0.3, (cx - 0.62, 0.0))
    phases = [("stand", 0.0, 0.3), ("approach", 0.3, t)]
    turn = [((cx - 0.62 + 0.17 * k / 4, 0.0), np.pi * k / 4) for k in range(1, 5)]
    t1 = g.walk(t, turn, period=0.55, swing=0.4, clearance=0.05, first=0)
    phases.append(("turn", t, t1))
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
    ts = _time_grid(t_end, fps)
    body = evaluate(ts, g, ch)
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
        pose=yaw_pose(np.tile([cx, 0.0, 0.0], (len(ts), 1)), np.pi),
        contact=seated,
        mass=CHAIR_MASS,
    )
    return make_demo(
        "SitStand", fps, body, target, [chair], phases, {"pelvis": seated, "left_hip": seated, "right_hip": seated}
    )


def push(rng, fps: float):
    bx = 2.2 + rng.uniform(-0.05, 0.05)
    g = GaitPlan((0.0, 0.0), 0.0)
    ch = Channels()
    face = bx - LARGE_BOX.size[0]
    t = g.walk_straight(0.3, (face - PUSH_STAND, 0.0))
    phases = [("stand", 0.0, 0.3), ("approach", 0.3, t)]
    ch.to(t, t + 0.7, hw=1.0, pp=0.10, sp=0.10)
    t_push = t + 0.8
    t1 = g.walk_straight(t_push, (face - PUSH_STAND + 1.0, 0.0), max_step=0.34, period=0.6, swing=0.45, clearance=0.05)
    ch.to(t1, t1 + 0.6, hw=0.0, pp=0.0, sp=0.0)
    t2 = g.walk_straight(t1 + 0.5, (face - PUSH_STAND + 0.7, 0.0), period=0.6, swing=0.42, clearance=0.04)
    t_end = t2 + 0.3
    phases += [
        ("reach", t, t + 0.7),
        ("brace", t + 0.7, t_push),
        ("push", t_push, t1),
        ("release", t1, t1 + 0.6),
        ("step_back", t1 + 0.5, t2),
        ("stand", t2, t_end),
    ]
    ts = _time_grid(t_end, fps)
    body = evaluate(ts, g, ch)
    i0 = np.searchsorted(ts, t_push)
    shift = np.clip(body.centre[:, 0] - body.centre[i0, 0], 0.0, None)
    shift[ts < t_push] = 0.0
    shift[ts > t1] = shift[ts <= t1][-1]
    pose = yaw_pose(np.column_stack([bx + shift, np.zeros(len(ts)), np.full(len(ts), LARGE_BOX.size[2])]), 0.0)
    hw = body.ch["hw"]
    target = grip_points(pose, LARGE_GRIP) + _approach([[-1.0, 0.0, 0.0]] * 2, hw, out=0.08, up=0.0)
    touch = hw >= 1.0
    obj = dict(
        name=OBJECT_NAME,
        geometry=LARGE_BOX,
        pose=pose,
        contact=touch,
        mass=LARGE_BOX_MASS,
        floor_friction=LARGE_BOX_FLOOR_FRICTION,
    )
    return make_demo("Push", fps, body, target, [obj], phases, {"left_wrist": touch, "right_wrist": touch})
