"""The mjlab (MuJoCo Warp) backend against the CPU environment at tiny scale (2 worlds, a few steps; mjlab runs on a
CPU, slowly): the same state gives the same observation and the same reward terms."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from pipeline.errors import InputError
from train import rewards as R
from train.env import EnvConfig, InteractionEnv
from train.post_env import PostEnvConfig, task_rewards
from train.randomize import RandomizationConfig, draw, stack

pytestmark = pytest.mark.slow

# every randomisation the mjlab worlds run, the per-step noises off so that one state gives one observation
NO_NOISE = replace(RandomizationConfig(), cylinder_prob=0.0, df_noise=(0.0, 0.0, 0.0), action_noise_rad=0.0)


@pytest.fixture(scope="module")
def box_episodes(bc_corpus):
    return [e for e in bc_corpus[0] if e.task != "SitStand"]


@pytest.fixture(scope="module")
def mjlab_env(box_episodes):
    from train.mjlab_env import MjlabPostTrainEnv

    env = MjlabPostTrainEnv(box_episodes, 3, PostEnvConfig(envs=2, seed=1, randomization=NO_NOISE), device="cpu")
    yield env
    env.close()


def test_the_same_state_gives_the_same_observation_and_reward(box_episodes, mjlab_env):
    from train import mjlab_terms as M

    rng = np.random.default_rng(5)
    assignments = [(i, replace(draw(NO_NOISE, rng), cylinder=False)) for i in (0, 1)]
    assignments[0] = (0, replace(assignments[0][1], restitution=0.0))  # one world without, one with a contact spring
    assert assignments[1][1].restitution > 0
    cpu = InteractionEnv(EnvConfig())
    cpu.reset([(box_episodes[e], v.scale, v) for e, v in assignments])
    actions = [np.stack([box_episodes[e].simulated.action[t] for e, _ in assignments]) for t in range(6)]
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
        "proprio": M.proprio(env),
        "root_command": M.root_command(env, worlds),
        "df": M.interaction(env, worlds, links),
    }
    native, warp = cpu.slots[0].scene.model.opt, env.sim.mj_model.opt  # the solver options mjlab_env._options copies
    for name in ("timestep", "integrator", "cone", "impratio"):
        assert getattr(warp, name) == getattr(native, name), name
    obj = env.scene["object"]
    g, b = obj.indexing.geom_ids[0], obj.indexing.body_ids[0]
    for i, slot in enumerate(cpu.slots):  # the object as the CPU scene built it: size, mass, friction, restitution
        m0, b0 = slot.scene.model, slot.scene.object_body_id[slot.objects[0].name]
        g0 = int(np.flatnonzero(m0.geom_bodyid == b0)[0])
        for field, mine, want in [("geom_size", env.sim.model.geom_size[i, g], m0.geom_size[g0]),
                                 ("geom_friction", env.sim.model.geom_friction[i, g], m0.geom_friction[g0]),
                                 ("geom_solref", env.sim.model.geom_solref[i, g], m0.geom_solref[g0]),
                                 ("geom_solimp", env.sim.model.geom_solimp[i, g], m0.geom_solimp[g0]),
                                 ("body_mass", env.sim.model.body_mass[i, b], m0.body_mass[b0]),
                                 ("body_inertia", env.sim.model.body_inertia[i, b], m0.body_inertia[b0]),
                                 ("body_subtreemass", env.sim.model.body_subtreemass[i, [0, b]],
                                  m0.body_subtreemass[[0, b0]]),
                                 ("body_invweight0", env.sim.model.body_invweight0[i, b], m0.body_invweight0[b0]),
                                 ("dof_invweight0", env.sim.model.dof_invweight0[i, obj.indexing.free_joint_v_adr],
                                  m0.dof_invweight0[m0.body_dofadr[b0] : m0.body_dofadr[b0] + 6])]:  # fmt: skip
            np.testing.assert_allclose(np.asarray(mine.cpu()), want, rtol=1e-5, err_msg=f"world {i} {field}")
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


def test_a_step_restarts_and_hands_rsl_rl_what_the_cpu_environment_does(mjlab_env):
    """``policy`` is 3-step windows in flatten_windows' layout (a start fills its window), ``critic`` the current
    step; the style extras are the DF features and the AMP transition; a finished episode restarts."""
    env = mjlab_env
    env.env.reset()
    env.obs = env.env.reset()[0]
    obs = env.get_observations()
    dims = (93, 12, obs["critic"].shape[1] - 105)
    windows = torch.split(obs["policy"], [3 * d for d in dims], dim=1)
    for w, c, d in zip(windows, torch.split(obs["critic"], list(dims), dim=1), dims):
        torch.testing.assert_close(w.reshape(2, 3, d), c[:, None].expand(2, 3, d))
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


def test_a_chair_is_a_one_line_error(bc_corpus):
    from train.mjlab_terms import check_box_episodes

    chair = [e for e in bc_corpus[0] if e.task == "SitStand"]
    with pytest.raises(InputError, match="objects.*one free box, not Chair"):
        check_box_episodes(chair)


def test_one_post_training_iteration_on_the_mjlab_backend(bc_corpus):
    """`train-aip --backend mjlab` at smoke scale on the CPU: PPO, AIP and AMP over the mjlab worlds into
    runs/<RUN>/aip-mjlab/, a checkpoint and a report that names the backend; SitStand's chair is left to the CPU
    backend, and said."""
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
