"""The LessMimic viewer replica (train/export/voxel_field.py, train/export/demo_loop.py) on a stand-in export folder:
tiny ONNX models with the export's names and shapes, a constant action, the lessmimic_demo gains."""

import json
import shutil

import mujoco
import numpy as np
import pytest
import torch

from pipeline.distance.field import ObjectField
from pipeline.errors import InputError
from pipeline.geometry import Primitive
from pipeline.robot import G1_JOINT_NAMES, LESSMIMIC_DEMO_DF_BODIES, actuator_profile
from train.export.demo_loop import DemoLoop, DemoPolicy, evaluate_demo_loop
from train.export.voxel_field import build_grid, query_objects

ACTION = np.zeros(29)
ACTION[28] = 20.0  # right wrist yaw: clipped to 10, its torque saturates at 5 N m
INPUTS = {"proprio": 465, "movement_goal": 12, "task_condition": 2, "interaction_field": 320}


class _Policy(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.lin = torch.nn.Linear(sum(INPUTS.values()), 29)
        torch.nn.init.zeros_(self.lin.weight)
        self.lin.bias.data = torch.tensor(ACTION, dtype=torch.float32)

    def forward(self, proprio, movement_goal, task_condition, interaction_field):
        return self.lin(torch.cat([proprio, movement_goal, task_condition, interaction_field], -1))


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    folder, demo = tmp_path_factory.mktemp("demo"), actuator_profile("lessmimic_demo")
    torch.manual_seed(0)
    args = tuple(torch.zeros(1, n) for n in INPUTS.values())
    names = {"input_names": list(INPUTS), "output_names": ["action"], "dynamo": False}
    torch.onnx.export(_Policy(), args, folder / "policy.onnx", **names)
    names = {"input_names": ["state"], "output_names": ["latent"], "dynamic_axes": {"state": {0: "b"}}, "dynamo": False}
    torch.onnx.export(torch.nn.Linear(28, 64), (torch.zeros(1, 28),), folder / "latent_encoder.onnx", **names)
    config = {
        "policy_type": "interaction",
        "onnx": {"path": "policy.onnx"},
        "latent_encoder": {"path": "latent_encoder.onnx"},
        "sdf": {"query_body_names": list(LESSMIMIC_DEMO_DF_BODIES), "max_valid_distance": 1.0},
        "history_length": 5,
        "action_clip": 10.0,
        "policy_joint_names": list(G1_JOINT_NAMES),
        "stiffness": demo.kp.tolist(),
        "damping": demo.kd.tolist(),
        "default_joint_pos": [0.0] * 29,
        "control_type": "joint_position",
    }
    (folder / "interaction_policy.json").write_text(json.dumps(config))
    return folder


def test_voxel_grid_matches_the_exact_box_distance_within_its_interpolation_error():
    box = Primitive("box", (0.142109, 0.199646, 0.09564))  # the viewer's box OBJ: its grid is the facts' (section 5)
    grid = build_grid(box, ObjectField.from_geometry(box, "box"))
    np.testing.assert_allclose(grid.bbox_min, [-1.142109, -1.199646, -1.09564])
    np.testing.assert_allclose(grid.voxel, [0.05857, 0.06152, 0.05619], atol=1e-5)
    p = np.random.default_rng(0).uniform(grid.bbox_min, grid.bbox_max, (5000, 3))
    q = np.abs(p) - box.half_extents
    exact = np.where((q > 0).any(1), np.linalg.norm(np.maximum(q, 0), axis=1), np.abs(q.max(1)))
    d, _ = grid.lookup(p)
    near = exact < 0.95
    err = np.abs(d[near] - exact[near])  # measured: max 0.025 (a quarter of the diagonal), mean 0.0008
    assert err.max() < 0.5 * np.linalg.norm(grid.voxel) and err.mean() < 0.005
    yaw90 = np.array([[1.0, 0, 0, np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]])  # at x = 1, turned 90 deg
    d, g = query_objects([grid], yaw90, np.array([[1.0, 0.3, 0.0], [1.0, 0.0, 1.5], [9.0, 0, 0]]))
    np.testing.assert_allclose(d, [0.3 - 0.142109, 1.0, 1.0], atol=2e-3)  # local x is world y; far: (1, 0, 0, 0)
    np.testing.assert_allclose(g, [[0, 1, 0], [0, 0, 0], [0, 0, 0]], atol=1e-6)


def test_loop_feeds_the_documented_observation_and_applies_the_pd_law(bc_corpus, export):
    episode = next(e for e in bc_corpus[0] if e.task == "PickUp")
    loop = DemoLoop(DemoPolicy(export), episode)
    s0 = loop.slot.state
    exact = np.minimum(np.abs(loop.slot.fields.query(s0.body_pos, s0.objects).phi), 1.0)
    np.testing.assert_allclose(loop.interaction_state()[:7], exact, atol=0.03)  # the grid vs our exact field
    loop.step()
    p, goal = loop.feeds["proprio"][0], loop.feeds["movement_goal"][0]
    assert loop.feeds["proprio"].shape == (1, 465) and loop.feeds["movement_goal"].shape == (1, 12)
    np.testing.assert_allclose(p[:58], np.r_[s0.q, 0.05 * s0.qd], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(p[290:293], [0, 0, -1], atol=0.05)  # gravity, standing
    np.testing.assert_allclose(p[305:308], s0.ang_vel, atol=1e-6)
    for older in (slice(58, 290), slice(293, 305), slice(308, 320), slice(320, 465)):  # the first step: zeros
        assert not p[older].any()
    target = episode.simulated.robot.qpos[loop.slot.command[0]]
    np.testing.assert_allclose(goal[:3], [*(target[:2] - s0.root_pos[:2]), 0], atol=1e-4)  # yaw ~ 0
    rot = goal[3:9].reshape(3, 2)  # r00 r01 r10 r11 r20 r21
    np.testing.assert_allclose(rot.T @ rot, np.eye(2), atol=1e-5)
    assert not goal[9:].any()  # the target starts at rest
    np.testing.assert_array_equal(loop.feeds["task_condition"], [[1, 1]])
    blocks = np.linalg.norm(loop.feeds["interaction_field"].reshape(5, 64), axis=1)
    np.testing.assert_allclose(blocks, [1, 0, 0, 0, 0], atol=1e-5)

    s1 = loop.slot.state
    loop.step()
    p = loop.feeds["proprio"][0]
    np.testing.assert_allclose(p[:29], s1.q, atol=1e-6)
    np.testing.assert_allclose(p[58:87], s0.q, atol=1e-6)  # one step older
    np.testing.assert_allclose(p[320:349], np.clip(ACTION, -10, 10), atol=1e-6)  # the last clipped action
    assert not p[349:].any()
    np.testing.assert_allclose(np.linalg.norm(loop.feeds["interaction_field"].reshape(5, 64), axis=1)[:2], 1, atol=1e-5)

    m, demo = loop.slot.scene.model, actuator_profile("lessmimic_demo")
    assert m.opt.timestep == 0.002 and m.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert (m.actuator_biastype == 0).all() and (m.actuator_gainprm[:, 0] == 1).all()  # motors, gear 1
    np.testing.assert_allclose(m.dof_damping[6:35], 0.2)
    np.testing.assert_allclose(m.dof_frictionloss[6:35], 0.1)
    np.testing.assert_allclose(m.jnt_solimp[1:30, :3], [[0.97, 0.995, 0.001]] * 29)
    q, qd, ctrl = loop.slot.pd  # the last substep's state and the torque it applied
    low, high = m.actuator_ctrlrange.T
    np.testing.assert_allclose(ctrl, np.clip(demo.kp * (np.clip(ACTION, -10, 10) - q) - demo.kd * qd, low, high))
    assert ctrl[28] == 5.0 and high[1] == 88.0  # saturated wrist yaw; the hip roll at the viewer's 88 N m


def test_evaluation_cell_and_bad_folders(bc_corpus, export, tmp_path):
    cell = evaluate_demo_loop(export, bc_corpus[0], "PickUp", seeds=(0,), episodes_per_seed=1)
    assert cell["episodes"] == 1 and cell["per_seed"] == [cell["mean"]] and cell["episode_profiles"] == ["mjlab"]
    assert cell["falls"] in (0, 1) and 0 <= cell["ci95"][0] <= cell["mean"] <= cell["ci95"][1]
    bad = shutil.copytree(export, tmp_path / "bad")
    config = json.loads((bad / "interaction_policy.json").read_text())
    config["stiffness"][3] = 100.0
    (bad / "interaction_policy.json").write_text(json.dumps(config))
    with pytest.raises(InputError, match="stiffness: left_knee_joint 100, the lessmimic_demo profile's is 160"):
        DemoPolicy(bad)
    (bad / "policy.onnx").unlink()
    with pytest.raises(InputError, match="policy.onnx: file: missing"):
        DemoPolicy(bad)
