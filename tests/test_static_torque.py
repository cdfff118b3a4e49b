import mujoco
import numpy as np
import pytest

from physicalize.static_torque import UPPER_BODY_JOINTS, static_torque_figures, static_torques
from pipeline.robot import G1_JOINT_NAMES, HAND_BODIES, actuator_profile, default_qpos, g1_model


def _pose(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    quat = rng.normal(size=4)
    return np.r_[0.1, -0.2, 0.7, quat / np.linalg.norm(quat), rng.uniform(-0.4, 0.4, 29)]


def test_static_torques_are_mujocos_gravity_minus_the_hand_reactions():
    """tau_s = qfrc_bias(q, qd = 0) - J_k^T (-f_k): checked against MuJoCo on random poses and loads."""
    m = g1_model()
    d = mujoco.MjData(m)
    rng = np.random.default_rng(1)
    offset = np.array([[0.11, -0.01, 0.0], [0.11, 0.01, 0.0]])
    qpos = np.stack([_pose(s) for s in range(3)])
    force = rng.normal(0.0, 30.0, (3, 2, 3))
    tau = static_torques(qpos, (offset, force))
    dofs = [m.joint(j).dofadr[0] for j in UPPER_BODY_JOINTS]
    jac = np.zeros((3, m.nv))
    for t, q in enumerate(qpos):
        d.qpos[:], d.qvel[:] = q, 0.0
        mujoco.mj_forward(m, d)
        expected = d.qfrc_bias.copy()
        for k, body in enumerate(HAND_BODIES):
            b = m.body(body).id
            mujoco.mj_jac(m, d, jac, None, d.xpos[b] + d.xmat[b].reshape(3, 3) @ offset[k], b)
            expected += jac.T @ force[t, k]  # the hand carries -f_k: tau_s = g - J^T (-f_k)
        np.testing.assert_allclose(tau[t], expected[dofs], atol=1e-8)
    assert not np.allclose(static_torques(qpos), tau)  # the loads count


def test_figures_name_the_joint_and_time_of_the_heaviest_load():
    prof = actuator_profile("mjlab")
    qpos = np.repeat(default_qpos(prof)[None], 4, axis=0)
    light = static_torque_figures(qpos, None, prof.effort_limit, 50.0)
    assert light["reference_static_torque_ratio_max"] < 0.3
    force = np.zeros((4, 2, 3))
    force[2] = [[0.0, 0.0, 100.0], [0.0, 0.0, 100.0]]  # frame 2: the hands hold 20 kg
    heavy = static_torque_figures(qpos, (np.zeros((2, 3)), force), prof.effort_limit, 50.0)
    assert heavy["reference_static_torque_ratio_max"] > 2.0 * light["reference_static_torque_ratio_max"]
    assert heavy["reference_static_torque_at_s"] == pytest.approx(2 / 50.0)
    i = UPPER_BODY_JOINTS.index(
        heavy["reference_static_torque_joint"]
    )  # the named joint at the named frame carries the reported ratio
    tau = static_torques(qpos, (np.zeros((2, 3)), force))[2, i]
    assert abs(tau) / prof.effort_limit[G1_JOINT_NAMES.index(UPPER_BODY_JOINTS[i])] == pytest.approx(
        heavy["reference_static_torque_ratio_max"]
    )
