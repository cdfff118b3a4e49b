"""The six post-training randomisations (train.mdp.randomize), each changing what it says and nothing else."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.clip import ObjectTrack
from pipeline.geometry import Primitive
from train.mdp.randomize import (
    RandomizationConfig,
    Variation,
    actuation_noise,
    draw,
    object_physics,
    perception_noise,
    perturb_command,
    perturb_initial_state,
    placed,
    vary_shape,
)

BOX = ObjectTrack("box", Primitive("box", (0.2, 0.1, 0.15)), np.tile([1.0, 0.5, 0.15, 1, 0, 0, 0], (3, 1)), mass=2.0)


def _yaw(wxyz) -> float:
    w, x, y, z = wxyz
    return float(Rotation.from_quat([x, y, z, w]).as_euler("zyx")[0])


def test_draws_stay_in_their_ranges_and_off_draws_nothing():
    cfg, rng = RandomizationConfig(), np.random.default_rng(0)
    draws = [draw(cfg, rng) for _ in range(200)]
    scales = np.array([v.scale for v in draws])
    assert scales.min() >= 0.4 and scales.max() <= 1.6 and np.std(scales[:, 0] - scales[:, 1]) > 0.2  # per axis
    assert 0.3 < np.mean([v.cylinder for v in draws]) < 0.7
    assert all(0.5 <= v.mass_factor <= 1.5 and 0.0 <= v.restitution <= 0.3 for v in draws)
    assert max(abs(v.robot_offset[0]) for v in draws) <= 0.03 and max(abs(v.command_offset[2]) for v in draws) <= 0.05
    assert max(max(map(abs, v.joint_noise)) for v in draws) <= 0.03
    assert draw(RandomizationConfig.off(), rng) == Variation()


def test_a_box_becomes_a_cylinder_of_its_height_and_mean_half_width_only_when_drawn():
    cyl = vary_shape(BOX, Variation(cylinder=True))
    g = cyl.geometry
    assert g.kind == "cylinder" and g.size == pytest.approx((0.15, 0.15)) and g.scale == (1.0, 1.0, 1.0)
    np.testing.assert_array_equal(cyl.pose, BOX.pose)
    scaled = replace(BOX, geometry=BOX.geometry.scaled((2.0, 1.0, 0.5)))  # the draw's scale, then the shape
    g = vary_shape(scaled, Variation(cylinder=True)).geometry
    assert g.size == pytest.approx((0.25, 0.075)) and g.scale == (1.0, 1.0, 1.0)  # circular: MuJoCo's primitive
    assert vary_shape(BOX, Variation(cylinder=False)) is BOX
    ball = ObjectTrack("ball", Primitive("sphere", (0.1,)), BOX.pose)
    assert vary_shape(ball, Variation(cylinder=True)) is ball


def test_physical_properties_scale_mass_and_friction_and_set_restitution():
    p = object_physics(
        replace(BOX, floor_friction=0.3), Variation(mass_factor=1.5, friction_factor=0.5, restitution=0.2)
    )
    assert (p.mass, p.friction, p.floor_friction, p.restitution) == pytest.approx((3.0, 0.4, 0.15, 0.2))


def test_initial_state_offsets_move_the_root_the_objects_and_the_joints_within_their_range():
    qpos = np.zeros(43)
    qpos[:7] = [0.1, 0.2, 0.79, 1, 0, 0, 0]
    qpos[36:43] = BOX.pose[0]
    joint_range = np.tile([-0.5, 0.02], (29, 1))
    v = Variation(robot_offset=(0.03, -0.02, 0.05), object_offset=(-0.01, 0.02, -0.1), joint_noise=(0.03,) * 29)
    perturb_initial_state(qpos, joint_range, [36], v)
    np.testing.assert_allclose(qpos[:3], [0.13, 0.18, 0.79])
    assert _yaw(qpos[3:7]) == pytest.approx(0.05)
    np.testing.assert_allclose(qpos[7:36], 0.02)  # 0 + 0.03 clipped to the upper limit
    np.testing.assert_allclose(qpos[36:39], [0.99, 0.52, 0.15])
    assert _yaw(qpos[39:43]) == pytest.approx(-0.1)
    np.testing.assert_allclose(placed(BOX, v)[:3], [0.99, 0.52, 0.15])


def test_the_command_target_is_shifted_and_turned():
    target = np.array([1.0, 0.0, 0.8, np.cos(0.2), 0, 0, np.sin(0.2)])  # yaw 0.4
    out = perturb_command(target, Variation(command_offset=(0.05, -0.05, 0.1)))
    np.testing.assert_allclose(out[:3], [1.05, -0.05, 0.8])
    assert _yaw(out[3:]) == pytest.approx(0.5)
    np.testing.assert_array_equal(target[:3], [1.0, 0.0, 0.8])  # the input is not changed


def test_actuation_and_perception_noise_have_their_spread_per_part():
    rng = np.random.default_rng(1)
    a = np.zeros((4000, 29))
    assert np.std(actuation_noise(a, 0.02, rng)) == pytest.approx(0.02, rel=0.02)
    assert actuation_noise(a, 0.0, rng) is a
    df = np.zeros((4000, 30))  # three links x u (10)
    noisy = perception_noise(df, (0.005, 0.02, 0.05), rng).reshape(-1, 3, 10)
    std = noisy.std(axis=(0, 1))
    np.testing.assert_allclose(std, [0.005] + [0.02] * 3 + [0.05] * 6, rtol=0.05)
    assert perception_noise(df, (0.0, 0.0, 0.0), rng) is df


def test_the_gpu_backend_draws_and_perturbs_with_the_same_functions_in_torch():
    """draw_batch with a torch.Generator stays in the ranges and repeats for a seed; perturbed_initial_state gives
    the same scenes in numpy and torch."""
    import torch

    from train.mdp.randomize import draw_batch, perturbed_initial_state, stack

    cfg = RandomizationConfig()
    b = draw_batch(cfg, 500, torch.Generator().manual_seed(3))
    again = draw_batch(cfg, 500, torch.Generator().manual_seed(3))
    assert all(torch.equal(b[k], again[k]) for k in b)
    assert 0.4 <= float(b["scale"].min()) and float(b["scale"].max()) <= 1.6 and b["scale"].shape == (500, 3)
    assert float(b["joint_noise"].abs().max()) <= 0.03 and float(b["command_offset"][:, 2].abs().max()) <= 0.05
    assert 0.4 < float(b["cylinder"].double().mean()) < 0.6
    variations = [draw(cfg, np.random.default_rng(s)) for s in range(4)]
    qpos = np.tile(np.concatenate([[0.1, 0.2, 0.79, 1, 0, 0, 0], np.full(29, 0.5), BOX.pose[0]]), (4, 1))
    joint_range = np.tile([-0.52, 0.52], (29, 1))
    s = stack(variations)
    args = [s["robot_offset"], s["object_offset"], s["joint_noise"]]
    want = perturbed_initial_state(qpos, joint_range, [36], *args)
    got = perturbed_initial_state(torch.as_tensor(qpos), joint_range, [36], *map(torch.as_tensor, args))
    np.testing.assert_allclose(got.numpy(), want, atol=1e-12)
    one = qpos[0].copy()
    perturb_initial_state(one, joint_range, [36], variations[0])
    np.testing.assert_array_equal(one, want[0])
    assert float(want[:, 7:36].max()) <= 0.52
