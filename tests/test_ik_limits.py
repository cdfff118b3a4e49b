"""The IKs' QP limits (pipeline/ik_limits.py): rows are the rates of MuJoCo's own distances,
penetrations are pushed out, MuJoCo's pair filtering, whole-frame speed budgets."""

from __future__ import annotations

import math

import bench_scripts
import mink
import mujoco
import numpy as np
import pytest

from pipeline.ik_limits import FloorLimit, FrameVelocityLimit, SeparationLimit, pairs_kept_apart_by_joint_limits
from pipeline.robot import G1_JOINT_NAMES
from pipeline.scene import build_scene
from retarget.ik_config import ik_model

bench_ik = bench_scripts.load("bench_ik")


@pytest.fixture(scope="module")
def plain():
    return build_scene()


def _rate_of_distance(model, data, g1, g2, dq):
    """Finite-difference change of the signed distance of (g1, g2) along the tangent step ``dq``."""
    q0 = data.qpos.copy()
    d0 = mujoco.mj_geomDistance(model, data, g1, g2, 1.0, None)
    q1 = q0.copy()
    mujoco.mj_integratePos(model, q1, dq, 1.0)
    data.qpos[:] = q1
    mujoco.mj_kinematics(model, data)
    d1 = mujoco.mj_geomDistance(model, data, g1, g2, 1.0, None)
    data.qpos[:] = q0
    mujoco.mj_kinematics(model, data)
    return d1 - d0


@pytest.mark.parametrize("lift", [0.02, -0.004])  # foot above the floor / sunk into it
def test_separation_limit_rows_are_distance_rates_and_push_out(plain, lift):
    m = plain.model
    cfg = mink.Configuration(m, bench_ik.demo_qpos(m, 2, turn=0.0, travel=0.0)[0])
    cfg.data.qpos[2] += lift
    cfg.update()
    floor, foot = m.geom("floor").id, m.geom("left_foot4_collision").id
    lim = SeparationLimit(
        m, [([foot], [floor])], gain=0.5, minimum_distance_from_collisions=0.0, collision_detection_distance=0.05
    )
    G, h = lim.compute_qp_inequalities(cfg, 1.0)
    d = mujoco.mj_geomDistance(m, cfg.data, floor, foot, 1.0, None)
    assert G.shape == (1, m.nv) and h[0] == pytest.approx(0.5 * d)
    dq = np.zeros(m.nv)
    dq[2] = 1e-4  # raise the root: the distance grows at the row's rate
    assert -(G[0] @ dq) == pytest.approx(_rate_of_distance(m, cfg.data, floor, foot, dq), rel=1e-3)
    lim.relaxed = True
    assert lim.compute_qp_inequalities(cfg, 1.0).h[0] == pytest.approx(max(0.5 * d, 0.0))


def test_pelvis_is_checked_against_objects_and_floor(plain):
    scene, _ = bench_ik.box_scene(plain.model, bench_ik.demo_qpos(plain.model, 20))
    m = ik_model(scene)
    pelvis, box, floor = m.geom("pelvis_collision").id, m.geom("box_col0").id, m.geom("floor").id
    lim = SeparationLimit(m, [([pelvis], [box, floor])])
    assert sorted(lim.geom_id_pairs) == sorted(
        [(min(pelvis, box), max(pelvis, box)), (min(pelvis, floor), max(pelvis, floor))]
    )
    excluded = SeparationLimit(m, [([pelvis], [m.geom("left_hip_collision").id])])  # <exclude> in g1.xml
    assert excluded.geom_id_pairs == []


def test_frame_velocity_limit_bounds_the_whole_frame(plain):
    m = plain.model
    cfg = mink.Configuration(m, bench_ik.demo_qpos(m, 2)[0])
    lim = FrameVelocityLimit(m, {"left_knee_joint": 10.0}, dt=0.1)
    lim.start_frame(cfg.q)
    assert lim.compute_qp_inequalities(cfg, 1.0).h == pytest.approx([1.0, 1.0])
    q = cfg.q.copy()
    q[7 + G1_JOINT_NAMES.index("left_knee_joint")] += 0.4
    cfg.update(q)
    assert lim.compute_qp_inequalities(cfg, 1.0).h == pytest.approx([0.6, 1.4])


@pytest.mark.parametrize("lift", [0.03, 0.0, -0.004])
def test_floor_limit_matches_mujoco_distances(plain, lift):
    m = plain.model
    q = bench_ik.demo_qpos(m, 40, turn=0.0, travel=0.0)[10]  # squatting: tilted shins, level feet
    q[2] += lift
    q[3:7] = [math.cos(0.05), math.sin(0.05), 0.0, 0.0]  # rolled 0.1 rad: feet on an edge
    cfg = mink.Configuration(m, q)
    floor = m.geom("floor").id
    geoms = [
        m.geom(n).id
        for n in ("left_foot1_collision", "left_foot4_collision", "right_shin_collision", "pelvis_collision")
    ]
    lim = FloorLimit(m, geoms, floor, gain=1.0, minimum_distance=0.0, detection_distance=10.0)
    G, h = lim.compute_qp_inequalities(cfg, 1.0)
    assert G.shape == (8, m.nv)  # both ends of every capsule, the sphere twice
    for k, g in enumerate(geoms):
        assert min(h[k], h[k + 4]) == pytest.approx(mujoco.mj_geomDistance(m, cfg.data, floor, g, 10.0, None), abs=1e-9)
    rng = np.random.default_rng(0)
    dq = 1e-5 * rng.standard_normal(m.nv)
    q1 = cfg.q.copy()
    mujoco.mj_integratePos(m, q1, dq, 1.0)
    h1 = lim.compute_qp_inequalities(mink.Configuration(m, q1), 1.0).h
    np.testing.assert_allclose(-(G @ dq), h1 - h, atol=1e-9)  # rows are the distance rates


def test_pairs_kept_apart_by_joint_limits_are_the_ankle_ones(plain):
    m = plain.model
    lim = SeparationLimit(m, [(list(plain.robot_geom_ids), list(plain.robot_geom_ids))], skip_kept_apart=False)
    kept = pairs_kept_apart_by_joint_limits(m, lim.geom_id_pairs)
    names = {(m.geom(a).name, m.geom(b).name) for a, b in kept}
    assert len(names) == 28 and all(("shin" in a or "brace" in a) and "foot" in b and a[:4] == b[:4] for a, b in names)
    brace, foot = m.geom("left_linkage_brace_collision").id, m.geom("left_foot5_collision").id
    d, (p, r) = mujoco.MjData(m), (m.joint("left_ankle_pitch_joint"), m.joint("left_ankle_roll_joint"))
    d.qpos[p.qposadr[0]], d.qpos[r.qposadr[0]] = m.jnt_range[p.id, 0], m.jnt_range[r.id, 1]  # the closest corner
    mujoco.mj_kinematics(m, d)
    assert 0.0 < mujoco.mj_geomDistance(m, d, brace, foot, 1.0, None) < 0.01
    assert (
        len(
            SeparationLimit(
                m, [(list(plain.robot_geom_ids), list(plain.robot_geom_ids))], skip_kept_apart=True
            ).geom_id_pairs
        )
        == len(lim.geom_id_pairs) - 28
    )
