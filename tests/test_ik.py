"""Retarget IK (retarget/ik.py): round trips on the G1's own forward kinematics.

Targets are world poses of 14 G1 bodies along a known G1 motion (bench/bench_ik.py
``demo_qpos``: squat, arm reach, waist twist, turn, travel), so the IK has an exact answer.
"""

from __future__ import annotations

import math

import bench_scripts
import mink
import mujoco
import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.geometry import Primitive
from pipeline.robot import G1_JOINT_NAMES, G1_LINK_NAMES, default_qpos, joint_limits, joint_velocity_limits
from pipeline.scene import SceneObject, build_scene
from retarget.ik import G1Retargeter, solve_sequence
from retarget.ik_config import IKConfig, ik_model, sole_offset
from retarget.targets import IKTargets, targets_from_qpos

bench_ik = bench_scripts.load("bench_ik")

FPS = 30.0
FRAMES = 120


@pytest.fixture(scope="module")
def plain():
    return build_scene()


@pytest.fixture(scope="module")
def turn_motion(plain):
    q = bench_ik.demo_qpos(plain.model, FRAMES)
    return q, targets_from_qpos(plain.model, q, G1_LINK_NAMES, FPS)


def body_positions(model, qpos, bodies=G1_LINK_NAMES) -> np.ndarray:
    d, ids = mujoco.MjData(model), [model.body(b).id for b in bodies]
    out = []
    for q in qpos:
        d.qpos[:36] = q
        mujoco.mj_kinematics(model, d)
        out.append(d.xpos[ids].copy())
    return np.array(out)


def contacts(scene, qpos, objects=None):
    """Worst (most negative) contact distance per kind over a trajectory: robot-robot, robot-object, robot-floor."""
    m, d = scene.model, mujoco.MjData(scene.model)
    robot, floor = set(scene.robot_geom_ids.tolist()), m.geom("floor").id
    worst = {"self": 0.0, "object": 0.0, "floor": 0.0}
    for t, q in enumerate(qpos):
        d.qpos[:36] = q
        for name, pose in (objects or {}).items():
            adr = scene.object_qpos_adr[name]
            d.qpos[adr : adr + 7] = pose[t]
        mujoco.mj_forward(m, d)
        for c in d.contact[: d.ncon]:
            r1, r2 = c.geom1 in robot, c.geom2 in robot
            kind = "self" if r1 and r2 else "floor" if floor in (c.geom1, c.geom2) else "object" if r1 or r2 else None
            if kind:
                worst[kind] = min(worst[kind], c.dist)
    return worst


def test_sole_offset_is_the_bottom_of_the_foot_capsules(plain):
    m = plain.model
    g = m.geom("left_foot4_collision").id  # centre 0.025 m below the ankle_roll_link origin, radius 0.01 m
    assert m.geom_pos[g, 2] == pytest.approx(-0.025) and m.geom_size[g, 0] == pytest.approx(0.01)
    for body in ("left_ankle_roll_link", "right_ankle_roll_link"):
        assert sole_offset(m, body) == pytest.approx(0.035, abs=2e-4)


def test_ik_model_has_the_scene_geoms_and_no_object_dofs(plain):
    scene, _ = bench_ik.box_scene(plain.model, bench_ik.demo_qpos(plain.model, 20))
    m = ik_model(scene)
    assert (m.nq, m.nv, m.nmocap) == (36, 35, 1)
    names = [scene.model.geom(g).name for g in range(scene.model.ngeom)]
    assert names == [m.geom(g).name for g in range(m.ngeom)]
    np.testing.assert_array_equal(m.geom_size, scene.model.geom_size)
    np.testing.assert_array_equal(m.geom_contype, scene.model.geom_contype)


def test_recovers_a_known_motion_within_limits(plain, turn_motion):
    q_true, targets = turn_motion
    ik = G1Retargeter(plain, IKConfig())
    q = ik.retarget(targets)
    assert q.shape == (FRAMES, 36) and np.isfinite(q).all()
    err = np.linalg.norm(body_positions(plain.model, q) - body_positions(plain.model, q_true), axis=-1)
    assert err.max() < 0.01, f"body position error {err.max():.4f} m"
    lo, hi = joint_limits()
    assert (q[:, 7:] >= lo - 1e-6).all() and (q[:, 7:] <= hi + 1e-6).all()
    vmax = np.array([joint_velocity_limits(ik.config.velocity_limit_factor)[j] for j in G1_JOINT_NAMES])
    assert (np.abs(np.diff(q[:, 7:], axis=0)) * FPS <= vmax + 1e-6).all()
    worst = contacts(plain, q)
    assert worst["self"] > -0.005 and worst["floor"] > -0.01, worst
    assert ik.stats["qp_solves"] <= ik.config.init_iterations + ik.config.iterations * (FRAMES - 1)


@pytest.mark.parametrize("pelvis_rot_weight", [0.1, 0.0])
def test_start_facing_backwards_far_from_the_default_pose(plain, pelvis_rot_weight):
    """Frame 0 at 180 deg yaw in a deep squat with the arm raised: no collapsed or stuck first frame."""
    q_true = bench_ik.demo_qpos(plain.model, 40, yaw0=math.pi, turn=0.0, travel=0.0, squat=0.5)
    q_true = q_true[10:]  # starts deep in the squat, right arm up
    rot = np.full(len(G1_LINK_NAMES), 0.1)
    rot[G1_LINK_NAMES.index("pelvis")] = pelvis_rot_weight
    targets = targets_from_qpos(plain.model, q_true, G1_LINK_NAMES, FPS, rot_weight=rot)
    q = solve_sequence(targets, plain, None, IKConfig())
    err = np.linalg.norm(body_positions(plain.model, q) - body_positions(plain.model, q_true), axis=-1)
    assert err[0].max() < 0.02 and err.max() < 0.02, err.max(axis=1)
    yaw = 2 * np.arctan2(q[:, 6], q[:, 3])
    assert np.all(np.abs(np.cos(yaw) + 1.0) < 0.01)  # heading stays at 180 deg


def _feet(model, q):
    """Per frame and foot: ankle xy, sole height (lowest capsule point), tilt of the sole normal."""
    d = mujoco.MjData(model)
    ids = [model.body(b).id for b in ("left_ankle_roll_link", "right_ankle_roll_link")]
    caps = [[g for g in range(model.ngeom) if model.geom_bodyid[g] == b and model.geom_contype[g]] for b in ids]
    xy, sole, tilt = [], [], []
    for qt in q:
        d.qpos[:36] = qt
        mujoco.mj_kinematics(model, d)
        xy.append(d.xpos[ids, :2].copy())
        sole.append([bench_ik._sole_height(model, d, c) for c in caps])
        tilt.append([math.acos(min(1.0, d.xmat[b, 8])) for b in ids])
    return np.array(xy), np.array(sole), np.array(tilt)


@pytest.mark.parametrize("anchor", ["target", "robot"])
def test_feet_in_contact_are_pinned_flat_on_the_ground(plain, anchor):
    """Foot targets drift 3 cm and bob 2 cm during contact: the robot feet neither slide nor float nor sink."""
    T = 90
    q_true = bench_ik.demo_qpos(plain.model, T, turn=0.0, travel=0.0)
    contact = np.ones((T, 2), bool)
    contact[:15, 1] = False  # right foot lands at frame 15
    targets = targets_from_qpos(plain.model, q_true, G1_LINK_NAMES, FPS, foot_contact=contact)
    pos = targets.pos.copy()
    s = np.linspace(0, 1, T)[:, None]
    for k in (G1_LINK_NAMES.index("left_ankle_roll_link"), G1_LINK_NAMES.index("right_ankle_roll_link")):
        pos[:, k, 0] += 0.03 * s[:, 0]
        pos[:, k, 2] += 0.02 * np.sin(6 * math.pi * s[:, 0])
    pos[:15, G1_LINK_NAMES.index("right_ankle_roll_link"), 2] += 0.05 * (1 - s[:15, 0] / s[15, 0])  # swing down
    targets = IKTargets(
        targets.body_names, pos, targets.quat, targets.pos_weight, targets.rot_weight, FPS, 1.0, contact
    )
    q = G1Retargeter(plain, IKConfig(pin_anchor=anchor)).retarget(targets)
    xy, sole, tilt = _feet(plain.model, q)
    for side in (0, 1):
        on = contact[:, side]
        steps = np.linalg.norm(np.diff(xy[:, side], axis=0), axis=-1)[on[1:] & on[:-1]]
        assert steps.max() < 0.002, f"foot {side} slides {steps.max():.4f} m/frame"
        assert np.abs(sole[on, side]).max() < 0.003 and tilt[on, side].max() < 0.02
    assert sole.min() > -0.01  # never below ground (swinging foot included)


def test_marching_feet_pinned_in_stance_and_free_in_swing(plain):
    q_true, contact = bench_ik.march_qpos(plain.model, 120, steps=4)
    assert contact.all(axis=1).any() and not contact[:, 0].all() and not contact[:, 1].all()
    targets = targets_from_qpos(plain.model, q_true, G1_LINK_NAMES, FPS, foot_contact=contact)
    q = G1Retargeter(plain, IKConfig()).retarget(targets)
    err = np.linalg.norm(body_positions(plain.model, q) - body_positions(plain.model, q_true), axis=-1)
    assert err.max() < 0.01, err.max()  # the swing foot follows its target (stance pins sit <= 5 mm off it)
    xy, sole, _ = _feet(plain.model, q)
    for side in (0, 1):
        stay = contact[1:, side] & contact[:-1, side]
        assert np.linalg.norm(np.diff(xy[:, side], axis=0), axis=-1)[stay].max() < 0.002
        assert np.abs(sole[contact[:, side], side]).max() < 0.003
    assert sole.min() > -0.01 and sole.min(axis=1).max() < 0.02  # never sunk, never both feet up


def test_box_in_the_hands_way_is_not_penetrated(plain):
    q_true = bench_ik.demo_qpos(plain.model, FRAMES)
    targets = targets_from_qpos(plain.model, q_true, G1_LINK_NAMES, FPS)
    scene, box = bench_ik.box_scene(plain.model, q_true, depth=0.05)
    assert contacts(scene, q_true, {"box": box})["object"] < -0.04  # the targets do push into the box
    ik = G1Retargeter(scene, IKConfig())
    q = ik.retarget(targets, {"box": box})
    worst = contacts(scene, q, {"box": box})
    assert worst["object"] > -0.01 and worst["self"] > -0.005 and worst["floor"] > -0.01, worst
    vmax = np.array([joint_velocity_limits(ik.config.velocity_limit_factor)[j] for j in G1_JOINT_NAMES])
    speed = np.abs(np.diff(q[:, 7:], axis=0)) * FPS
    assert (speed <= vmax + 1e-6).all()
    v = np.diff(q[:, 7:], axis=0) * FPS
    chatter = (np.sign(v[1:]) != np.sign(v[:-1])) & (np.abs(v[1:]) > 2.0) & (np.abs(v[:-1]) > 2.0)
    assert not chatter.any() and speed.max() < 8.0  # the blocked arm does not oscillate (motion: <= 1.6 rad/s)
    np.testing.assert_allclose(ik.configuration.data.mocap_pos[0], box[-1, :3])


def test_joint_speed_limit_holds_for_a_target_jump(plain, turn_motion):
    q_true, targets = turn_motion
    pos = targets.pos.copy()
    pos[60:, G1_LINK_NAMES.index("right_wrist_yaw_link")] += [0.0, -0.2, 0.3]  # teleporting hand
    jumped = IKTargets(targets.body_names, pos, targets.quat, targets.pos_weight, targets.rot_weight, FPS, 1.0)
    config = IKConfig(velocity_limit_factor=0.2, iterations=3)
    q = solve_sequence(jumped, plain, None, config)
    vmax = np.array([joint_velocity_limits(0.2)[j] for j in G1_JOINT_NAMES])
    speed = np.abs(np.diff(q[:, 7:], axis=0)) * FPS
    assert (speed <= vmax + 1e-6).all() and (speed / vmax).max() > 0.99  # the limit binds and holds


def test_deterministic(plain, turn_motion):
    _, targets = turn_motion
    a = solve_sequence(targets, plain, None, IKConfig())
    b = solve_sequence(targets, plain, None, IKConfig())
    np.testing.assert_array_equal(a, b)


def test_nan_target_is_an_input_error_naming_clip_and_frame(plain, turn_motion):
    _, targets = turn_motion
    pos = targets.pos.copy()
    pos[7, 3, 1] = np.nan
    bad = IKTargets(targets.body_names, pos, targets.quat, targets.pos_weight, targets.rot_weight, FPS, 1.0)
    with pytest.raises(InputError, match=r"^clip\.npz: frame 7: IK target pos"):
        solve_sequence(bad, plain, None, IKConfig(), source="clip.npz")


def test_divergence_is_an_input_error_naming_the_frame(plain, turn_motion, monkeypatch):
    _, targets = turn_motion
    ik = G1Retargeter(plain, IKConfig())
    calls = {"n": 0}
    real = mink.solve_ik

    def flaky(*args, **kwargs):
        calls["n"] += 1
        v = real(*args, **kwargs)
        return v * np.nan if calls["n"] > ik.config.init_iterations + 2 * 4 else v

    monkeypatch.setattr(mink, "solve_ik", flaky)
    with pytest.raises(InputError, match=r"^walk\.bvh: frame \d+: qpos: IK diverged"):
        ik.retarget(targets, source="walk.bvh")


def test_bad_names_are_rejected(plain, turn_motion):
    _, targets = turn_motion
    with pytest.raises(ValueError, match="free objects"):
        solve_sequence(targets, plain, {"chair": np.zeros((FRAMES, 7))}, IKConfig())
    odd = IKTargets(("pelvis", "left_hand"), targets.pos[:, :2], targets.quat[:, :2], np.ones(2), np.ones(2), FPS, 1.0)
    with pytest.raises(ValueError, match="left_hand"):
        solve_sequence(odd, plain, None, IKConfig())
    with pytest.raises(ValueError, match="iterations"):
        IKConfig(iterations=0)


def test_box_set_down_onto_a_planted_toe_gives_way(plain):
    """A box lowered onto the right toe: the pinned foot stays, the box is moved clear and stays there."""
    T = 60
    q_true = np.repeat(default_qpos(plain.profile)[None], T, axis=0)
    contact = np.ones((T, 2), bool)
    targets = targets_from_qpos(plain.model, q_true, G1_LINK_NAMES, FPS, foot_contact=contact)
    d = mujoco.MjData(plain.model)
    d.qpos[:36] = q_true[0]
    mujoco.mj_kinematics(plain.model, d)
    toe = d.site_xpos[plain.model.site("right_foot").id] + [0.12, 0.0, 0.0]  # in front of the sole centre, over the toe
    box = np.zeros((T, 7))
    box[:, 3] = 1.0
    box[:, :2] = toe[:2] + [0.05, 0.0]  # the box's back face 3 cm behind the toe tip
    box[:, 2] = 0.08 + np.clip(np.linspace(0.25, -0.05, T), 0.0, None)  # comes down, then rests on the floor
    scene = build_scene([SceneObject("box", Primitive("box", (0.08, 0.08, 0.08)), pose=tuple(box[0]))])
    assert contacts(scene, q_true, {"box": box})["object"] < -0.02  # left where it is, the box would cut into the toe
    ik = G1Retargeter(scene, IKConfig())
    q = ik.retarget(targets, {"box": box})
    moved = ik.objects_pose["box"]
    assert contacts(scene, q, {"box": moved})["object"] > -0.002
    xy, _, _ = _feet(plain.model, q)
    assert np.linalg.norm(xy - xy[0], axis=-1).max() < 0.002  # the feet stay pinned
    shift = moved[:, :2] - box[:, :2]
    assert shift[-1, 0] > 0.02 and abs(shift[-1, 1]) < 0.01  # pushed forward, away from the foot
    np.testing.assert_allclose(shift[-5:], np.repeat(shift[-1:], 5, axis=0))  # and settles once it rests
    assert np.linalg.norm(np.diff(shift, axis=0), axis=-1).max() <= 1.0 / FPS + 1e-9  # at most clearance_speed
    np.testing.assert_array_equal(moved[:, 2:], box[:, 2:])  # heights and orientations untouched


def test_a_resting_box_at_a_planted_toe_stands_still_where_it_is_moved(plain):
    """A box standing on the floor over the right toe from the first frame: it is placed clear of the
    toe on every frame (it does not slide away while nobody touches it; a physics box cannot)."""
    T = 40
    q_true = np.repeat(default_qpos(plain.profile)[None], T, axis=0)
    targets = targets_from_qpos(plain.model, q_true, G1_LINK_NAMES, FPS, foot_contact=np.ones((T, 2), bool))
    d = mujoco.MjData(plain.model)
    d.qpos[:36] = q_true[0]
    mujoco.mj_kinematics(plain.model, d)
    toe = d.site_xpos[plain.model.site("right_foot").id] + [0.12, 0.0, 0.0]
    box = np.tile([toe[0] + 0.05, toe[1], 0.08, 1.0, 0.0, 0.0, 0.0], (T, 1))  # back face 3 cm behind the toe tip
    scene = build_scene([SceneObject("box", Primitive("box", (0.08, 0.08, 0.08)), pose=tuple(box[0]))])
    ik = G1Retargeter(scene, IKConfig())
    q = ik.retarget(targets, {"box": box})
    placed = ik.objects_pose["box"]
    assert placed[0, 0] - box[0, 0] > 0.02  # moved forward, away from the foot ...
    np.testing.assert_allclose(placed, np.tile(placed[0], (T, 1)))  # ... from the first frame on, and never slides
    assert contacts(scene, q, {"box": placed})["object"] > -0.002
