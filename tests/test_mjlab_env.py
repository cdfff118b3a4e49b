"""The mjlab (MuJoCo Warp) backend against the CPU environment at tiny scale (2 worlds, a few steps; mjlab runs on a
CPU, slowly): the same state gives the same observation and the same reward terms."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from pipeline.errors import InputError
from pipeline.geometry import Primitive
from train.envs.config import PostEnvConfig
from train.envs.cpu.env import EnvConfig, InteractionEnv
from train.envs.cpu.rewards import task_rewards
from train.envs.mjlab.object import MODEL_FIELDS
from train.mdp import rewards as R
from train.mdp.randomize import RandomizationConfig, draw, stack

pytestmark = pytest.mark.slow

# every randomisation the mjlab worlds run, the per-step noises off so that one state gives one observation
NO_NOISE = replace(RandomizationConfig(), df_noise=(0.0, 0.0, 0.0), action_noise_rad=0.0)


@pytest.fixture(scope="module")
def episodes(bc_corpus):
    return bc_corpus[0]


@pytest.fixture(scope="module")
def mjlab_env(episodes):
    from train.envs.mjlab.env import MjlabPostTrainEnv

    env = MjlabPostTrainEnv(episodes, 3, PostEnvConfig(envs=2, seed=1, randomization=NO_NOISE), device="cpu")
    yield env
    env.close()


@pytest.mark.parametrize("kinds", [("box", "chair"), ("cylinder", "box")])
def test_the_same_state_gives_the_same_observation_and_reward(episodes, mjlab_env, kinds):
    """Two worlds run the two ``kinds`` of object (a box episode, a chair's (SitStand), a box drawn as a cylinder),
    the first without restitution, the second with a contact spring, each at its own drawn per-axis scale: the model
    fields of its object are the CPU scene's, and so are the observations and the reward terms."""
    from train.envs.mjlab import observations as O
    from train.envs.mjlab import rewards as M

    rng = np.random.default_rng(5)
    box, chair = (next(i for i, e in enumerate(episodes) if (e.task == "SitStand") == c) for c in (False, True))
    pick = {"box": (box, False), "chair": (chair, False), "cylinder": (box, True)}
    assignments = [(pick[k][0], replace(draw(NO_NOISE, rng), cylinder=pick[k][1])) for k in kinds]
    assignments[0] = (assignments[0][0], replace(assignments[0][1], restitution=0.0))
    assert assignments[1][1].restitution > 0 and len(set(assignments[1][1].scale)) == 3
    cpu = InteractionEnv(EnvConfig())
    cpu.reset([(episodes[e], v.scale, v) for e, v in assignments])
    actions = [np.stack([episodes[e].simulated.action[t] for e, _ in assignments]) for t in range(6)]
    for a in actions:
        obs, _ = cpu.step(a)
    want_reward, want_terms = task_rewards(cpu, actions[-1], actions[-2], R.RewardWeights())

    env, worlds = mjlab_env.env, mjlab_env.worlds
    ids = torch.arange(2)
    worlds.start(env, ids, torch.tensor([e for e, _ in assignments]), stack([v for _, v in assignments]))
    d = env.sim.data
    d.qpos[:] = torch.as_tensor(np.stack([s.data.qpos for s in cpu.slots]), dtype=torch.float32)
    d.qvel[:] = torch.as_tensor(np.stack([s.data.qvel for s in cpu.slots]), dtype=torch.float32)
    env.sim.forward()
    env.episode_length_buf[:] = len(actions)
    for a in actions[-2:]:
        env.action_manager.process_action(torch.as_tensor(a, dtype=torch.float32))
    links = EnvConfig().links
    got = {
        "proprio": O.proprio(env),
        "root_command": O.root_command(env, worlds),
        "df": O.interaction(env, worlds, links),
    }
    native, warp = cpu.slots[0].scene.model.opt, env.sim.mj_model.opt  # what envs.mjlab.env._options copies
    for name in ("timestep", "integrator", "cone", "impratio"):
        assert getattr(warp, name) == getattr(native, name), name
    _check_object_fields(env, cpu)
    for key, atol in (("proprio", 1e-5), ("root_command", 1e-5), ("df", 1e-4)):
        np.testing.assert_allclose(got[key].numpy(), getattr(obs, key), atol=atol, err_msg=key)
    env.termination_manager.compute()
    terms = {
        "root_tracking": M.root_tracking(env, worlds),
        "object_tracking": M.object_tracking(env, worlds, R.RewardWeights().object_sigma_m),
        "action_rate": M.action_rate(env),
        "termination": M.termination(env),
        "joint_limits": M.joint_limits(env, worlds, R.RewardWeights().soft_limit),
    }
    for k, v in terms.items():
        assert float(v.mean()) == pytest.approx(want_terms[k], rel=1e-4, abs=1e-6), k
    assert float(R.total(terms, R.RewardWeights()).sum()) == pytest.approx(float(want_reward.sum()), rel=1e-4)
    assert want_terms["action_rate"] > 0 and 0 < want_terms["object_tracking"] < 1  # the terms are not trivially 0


def _check_object_fields(env, cpu) -> None:
    """Each world's object as the CPU scene built it: part sizes and positions, friction (with the robot; the floor
    pairs'), restitution, mass, inertia
    (the tensor about the centre of mass: MuJoCo's principal axes may come in another order) and the constants
    ``mj_setConst`` derives."""
    import mujoco

    obj = env.scene["object"]
    g, b = np.asarray(obj.indexing.geom_ids.cpu()), int(obj.indexing.body_ids[0])
    dofs = np.asarray(obj.indexing.free_joint_v_adr.cpu())
    mine = {k: np.asarray(getattr(env.sim.model, k).cpu(), dtype=float) for k in MODEL_FIELDS}

    def tensor(quat, diag):
        r = np.empty(9)
        mujoco.mju_quat2Mat(r, quat)
        return r.reshape(3, 3) @ np.diag(diag) @ r.reshape(3, 3).T

    for i, slot in enumerate(cpu.slots):
        m0, b0 = slot.scene.model, slot.scene.object_body_id[slot.objects[0].name]
        g0 = np.flatnonzero(m0.geom_bodyid == b0)
        k = len(g0)
        gi = g[-1:] if m0.geom_type[g0[0]] == mujoco.mjtGeom.mjGEOM_CYLINDER else g[:k]  # the cylinder slot is last
        pairs = [("geom_size", mine["geom_size"][i, gi], m0.geom_size[g0]),
                 ("geom_pos", mine["geom_pos"][i, gi], m0.geom_pos[g0]),
                 ("geom_rbound", mine["geom_rbound"][i, gi], m0.geom_rbound[g0]),
                 ("geom_aabb", mine["geom_aabb"][i, gi].reshape(len(gi), 6), m0.geom_aabb[g0]),
                 ("geom_friction", mine["geom_friction"][i, gi], m0.geom_friction[g0]),
                 ("geom_solref", mine["geom_solref"][i, gi], m0.geom_solref[g0]),
                 ("geom_solimp", mine["geom_solimp"][i, gi], m0.geom_solimp[g0]),
                 ("pair_friction", mine["pair_friction"][i], np.broadcast_to(m0.pair_friction[0], (len(g), 5))),
                 ("pair_solref", mine["pair_solref"][i], np.broadcast_to(m0.pair_solref[0], (len(g), 2))),
                 ("pair_solimp", mine["pair_solimp"][i], np.broadcast_to(m0.pair_solimp[0], (len(g), 5))),
                 ("body_mass", mine["body_mass"][i, b], m0.body_mass[b0]),
                 ("body_ipos", mine["body_ipos"][i, b], m0.body_ipos[b0]),
                 ("inertia tensor", tensor(mine["body_iquat"][i, b], mine["body_inertia"][i, b]),
                  tensor(m0.body_iquat[b0], m0.body_inertia[b0])),
                 ("body_subtreemass", mine["body_subtreemass"][i, [0, b]], m0.body_subtreemass[[0, b0]]),
                 ("body_invweight0", mine["body_invweight0"][i, b], m0.body_invweight0[b0]),
                 ("dof_invweight0", mine["dof_invweight0"][i, dofs],
                  m0.dof_invweight0[m0.body_dofadr[b0] : m0.body_dofadr[b0] + 6])]  # fmt: skip
        for field, got, want in pairs:
            np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7, err_msg=f"world {i} ({k} parts) {field}")
        pads = np.setdiff1d(g, gi)
        assert (mine["geom_size"][i, pads] <= 1e-4).all()  # the slots this world does not use (train.envs.mjlab.object)


def test_a_restart_sizes_each_world_by_its_episode_and_draw(bc_corpus):
    """:meth:`train.envs.mjlab.object.Shapes.at` (no mjlab; here for the corpus this file builds): a chair world takes
    :meth:`Chair.scaled`'s parts; a box world its box and five pads at its centre; a box drawn as a cylinder the
    box's mean scaled half-width and half-height, every box part a pad; a chair's cylinder draw is ignored.
    :meth:`Shapes.floor_shift` raises a box (and its cylinder) by its half-height's change, never a chair."""
    from pipeline.geometry import Chair
    from train.envs.mjlab.object import PAD_HALF, Shapes

    episodes = bc_corpus[0]
    box, chair = (next(i for i, e in enumerate(episodes) if (e.task == "SitStand") == c) for c in (False, True))
    shapes = Shapes(episodes, torch.device("cpu"), cylinder_prob=0.5)
    assert shapes.parts == 6 and shapes.cylinders
    scale = torch.tensor([[0.5, 1.2, 1.5]] * 3)
    episode = torch.tensor([chair, box, box])
    p = shapes.at(episode, scale, torch.tensor([1.0, 0.0, 1.0]))
    parts = Chair(**episodes[chair].simulated.robot.objects[0].geometry.__dict__).scaled(scale[0].numpy()).parts()
    np.testing.assert_allclose(p.half[0].numpy(), [b.half_extents for _, b, _ in parts], rtol=1e-6)
    np.testing.assert_allclose(p.centre[0].numpy(), [c for _, _, c in parts], rtol=1e-6, atol=1e-7)
    half = episodes[box].simulated.robot.objects[0].geometry.half_extents * scale[1].numpy()
    np.testing.assert_allclose(p.half[1, 0].numpy(), half, rtol=1e-6)
    assert (p.half[1, 1:] == PAD_HALF).all() and (p.centre[1:] == 0).all() and (p.half[2] == PAD_HALF).all()
    assert p.real[0].all() and p.real[1].tolist() == [True] + [False] * 5 and not p.real[2].any()
    assert p.cylinder.tolist() == [False, False, True]
    assert float(p.radius[2]) == pytest.approx((half[0] + half[1]) / 2) and float(p.length[2]) == pytest.approx(half[2])
    shift = shapes.floor_shift(episode, scale).numpy()
    assert shift[0] == 0 and shift[1] == shift[2] == pytest.approx(half[2] - half[2] / 1.5)


def test_a_step_restarts_and_hands_rsl_rl_what_the_cpu_environment_does(mjlab_env):
    """``policy`` is 3-step windows in ObservationLayout.flatten's order (a start fills its window), ``critic`` the
    current
    step; the style extras are the DF features and the AMP transition; a finished episode restarts."""
    from train.envs.mjlab import observations as O

    env = mjlab_env
    env.env.reset()
    env.obs = env.env.reset()[0]
    obs = env.get_observations()
    dims = (93, 12, obs["critic"].shape[1] - 105)
    windows = torch.split(obs["policy"], [3 * d for d in dims], dim=1)
    for w, c, d in zip(windows, torch.split(obs["critic"], list(dims), dim=1), dims):
        torch.testing.assert_close(w.reshape(2, 3, d), c[:, None].expand(2, 3, d))
    worlds, links = env.worlds, EnvConfig().links  # the managers' terms read the episodes the restarts wrote
    direct = [O.proprio(env.env), O.root_command(env.env, worlds), O.interaction(env.env, worlds, links)]
    torch.testing.assert_close(obs["critic"], torch.cat(direct, 1))
    assert len(set(worlds.episode.tolist())) == 2  # the two worlds run two episodes (seed 1)
    hold = obs["critic"][:, :29].clone()
    before = obs["critic"][:, :64].clone()
    nxt, reward, done, extras = env.step(hold)
    torch.testing.assert_close(extras["style"]["transition"][:, :64], before)
    torch.testing.assert_close(extras["style"]["transition"][:, 64:], nxt["critic"][:, :64])
    torch.testing.assert_close(nxt["policy"][:, 2 * 93 : 3 * 93], nxt["critic"][:, :93])
    assert reward.shape == (2,) and torch.isfinite(reward).all() and not done.any()
    assert extras["log"]["/reward/action_rate"] == 0.0  # an episode's first step
    env.env.episode_length_buf[:] = env.worlds.frames[env.worlds.episode] - 2  # one step before the reference ends
    _, _, done, extras = env.step(hold)
    assert done.all() and extras["time_outs"].all()
    assert (env.env.episode_length_buf == 0).all()


def test_an_object_neither_box_nor_chair_is_a_one_line_error(bc_corpus):
    from train.envs.mjlab.worlds import check_episodes

    e = bc_corpus[0][0]
    robot = e.simulated.robot
    ball = replace(robot.objects[0], geometry=Primitive("sphere", (0.2,)))
    ball_episode = replace(e, simulated=replace(e.simulated, robot=replace(robot, objects=(ball,))))
    check_episodes(bc_corpus[0])
    with pytest.raises(InputError, match="objects.*one box or chair, not sphere"):
        check_episodes([ball_episode])


def test_one_post_training_iteration_on_the_mjlab_backend(bc_corpus):
    """`train-aip --backend mjlab` at smoke scale on the CPU: PPO, AIP and AMP over the mjlab worlds into
    runs/<RUN>/aip-mjlab/, a checkpoint and a report that names the backend."""
    import json

    from lessmimic.cli import main

    run = bc_corpus[1].parent
    args = ["--iterations", "1", "--steps-per-env", "4", "--envs", "2", "--device", "cpu"]
    assert main(["train-aip", "--name", "train", "--run", str(run), "--backend", "mjlab", *args]) == 0
    out = run / "aip-mjlab"
    row = json.loads((out / "post_log.jsonl").read_text().splitlines()[-1])
    assert row["env_steps"] == 8 and np.isfinite(row["task_reward"]) and "aip_reward" in row
    assert (out / "policy.pt").is_file() and not (run / "aip").exists()
    post = json.loads((out / "report.json").read_text())["scale"]["post_training"]
    assert post["backend"] == "mjlab" and post["envs"] == 2


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_mjlab_without_a_gpu_is_a_one_line_error(bc_corpus, capsys):
    from lessmimic.cli import main

    assert main(["train-aip", "--name", "train", "--run", str(bc_corpus[1].parent), "--backend", "mjlab"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "needs a CUDA GPU" in err[0], err
    assert main(["train-aip", "--name", "train", "--run", str(bc_corpus[1].parent), "--backend", "gpu"]) == 2
    assert "unknown backend 'gpu'" in capsys.readouterr().err
