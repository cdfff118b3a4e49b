"""The G1 definition agrees with the installed mjlab model and constants."""

import mujoco
import numpy as np
import pytest

from pipeline.robot import (
    ACTUATOR_PROFILES,
    G1_JOINT_NAMES,
    G1_LINK_NAMES,
    LESSMIMIC_DEMO_DF_BODIES,
    actuator_profile,
    g1_model,
    g1_xml_path,
    joint_limits,
)


def test_joint_order_is_the_mjlab_xml_order():
    m = mujoco.MjModel.from_xml_path(str(g1_xml_path()))
    assert (m.nq, m.nv) == (36, 35)
    assert tuple(m.joint(i).name for i in range(1, m.njnt)) == G1_JOINT_NAMES


def test_physics_model_without_visual_meshes_has_the_xml_physics():
    full, lean = mujoco.MjModel.from_xml_path(str(g1_xml_path())), g1_model()
    assert lean.nmesh == 0 and full.nmesh > 0
    for field in (
        "body_mass",
        "body_inertia",
        "body_ipos",
        "body_iquat",
        "body_pos",
        "body_quat",
        "jnt_range",
        "dof_armature",
        "dof_damping",
    ):
        np.testing.assert_array_equal(getattr(lean, field), getattr(full, field), err_msg=field)

    def collision(m):
        return [
            (
                m.geom(g).name,
                m.geom_bodyid[g],
                m.geom_type[g],
                *m.geom_size[g],
                *m.geom_pos[g],
                *m.geom_quat[g],
                *m.geom_friction[g],
            )
            for g in range(m.ngeom)
            if m.geom_contype[g] or m.geom_conaffinity[g]
        ]

    assert collision(lean) == collision(full) and len(collision(lean)) > 20
    # the same contacts and dynamics at a crouched, tilted pose
    dl, df = mujoco.MjData(lean), mujoco.MjData(full)
    quat = np.array([0.96, 0.1, 0.2, 0.0])
    q = np.r_[0.1, 0.0, 0.55, quat / np.linalg.norm(quat), np.random.default_rng(0).uniform(-0.3, 0.3, 29)]
    for m, d in ((lean, dl), (full, df)):
        d.qpos[:] = q
        mujoco.mj_forward(m, d)
    assert dl.ncon == df.ncon
    np.testing.assert_array_equal(dl.qacc, df.qacc)


def test_named_links_exist():
    m = mujoco.MjModel.from_xml_path(str(g1_xml_path()))
    for b in G1_LINK_NAMES + LESSMIMIC_DEMO_DF_BODIES:
        m.body(b)  # raises KeyError when missing


def test_constants_match_mjlab_g1_constants():
    import re

    from mjlab.asset_zoo.robots.unitree_g1 import g1_constants as c

    prof = ACTUATOR_PROFILES["mjlab"]
    for act in c.G1_ARTICULATION.actuators:
        for i, j in enumerate(G1_JOINT_NAMES):
            if any(re.fullmatch(expr, j) for expr in act.target_names_expr):
                assert prof.kp[i] == pytest.approx(act.stiffness)
                assert prof.kd[i] == pytest.approx(act.damping)
                assert prof.effort_limit[i] == pytest.approx(act.effort_limit)
                assert prof.armature[i] == pytest.approx(act.armature)
    for pattern, value in c.KNEES_BENT_KEYFRAME.joint_pos.items():
        for i, j in enumerate(G1_JOINT_NAMES):
            if re.fullmatch(pattern, j):
                assert prof.default_joint_pos[i] == pytest.approx(value)


def test_field_notes_gains():
    kp = ACTUATOR_PROFILES["mjlab"].kp
    i = G1_JOINT_NAMES.index
    assert kp[i("left_hip_pitch_joint")] == pytest.approx(40.2, abs=0.05)
    assert kp[i("left_knee_joint")] == pytest.approx(99.1, abs=0.05)
    assert kp[i("left_ankle_pitch_joint")] == pytest.approx(28.5, abs=0.05)
    assert kp[i("left_elbow_joint")] == pytest.approx(14.3, abs=0.05)
    assert kp[i("left_wrist_yaw_joint")] == pytest.approx(16.8, abs=0.05)
    demo = actuator_profile("lessmimic_demo")
    assert demo.kp[i("left_knee_joint")] == 160 and demo.kp[i("waist_pitch_joint")] == 200
    assert demo.kd[i("right_wrist_pitch_joint")] == 0.5 and demo.action_clip == 10
    assert not demo.default_joint_pos.any()


def test_joint_limits_and_torque_clip():
    lo, hi = joint_limits()
    assert lo.shape == hi.shape == (29,) and (lo < hi).all()
    assert lo[G1_JOINT_NAMES.index("left_knee_joint")] == pytest.approx(-0.087267)
    prof = actuator_profile("mjlab")
    tau = prof.torque(np.full(29, 10.0), np.zeros(29), np.zeros(29))
    np.testing.assert_allclose(tau, prof.effort_limit)


def test_unknown_profile():
    with pytest.raises(ValueError, match="unknown actuator profile 'pd'"):
        actuator_profile("pd")


def test_pinocchio_builds_the_same_model():
    import pinocchio

    from pipeline.robot import g1_pinocchio_model, pinocchio_qpos

    pm = g1_pinocchio_model()
    mj = mujoco.MjModel.from_xml_path(str(g1_xml_path()))
    assert (pm.nq, pm.nv) == (mj.nq, mj.nv)
    assert tuple(pm.names)[2:] == G1_JOINT_NAMES
    assert pinocchio.computeTotalMass(pm) == pytest.approx(mj.body_mass.sum())
    rng = np.random.default_rng(0)
    root_quat = np.array([0.9, 0.1, -0.2, 0.3]) / np.linalg.norm([0.9, 0.1, -0.2, 0.3])
    qpos = np.r_[0.1, -0.2, 0.8, root_quat, rng.uniform(-0.4, 0.4, 29)]
    pd = pm.createData()
    pinocchio.framesForwardKinematics(pm, pd, pinocchio_qpos(qpos))
    md = mujoco.MjData(mj)
    md.qpos[:] = qpos
    mujoco.mj_kinematics(mj, md)
    for body in G1_LINK_NAMES:
        np.testing.assert_allclose(pd.oMf[pm.getFrameId(body)].translation, md.xpos[mj.body(body).id], atol=1e-9)
