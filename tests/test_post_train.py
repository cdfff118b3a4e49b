"""Post-training (PPO + AIP + AMP through rsl_rl) at smoke scale on the default corpus: real retarget ->
physicalize -> features datasets, a BC policy trained for a few steps, real MuJoCo."""

import json
import zipfile
from dataclasses import replace

import numpy as np
import pytest
import torch

from pipeline.errors import InputError
from pipeline.terms.layout import AMP_STATE
from train.aip import PostTrainConfig, post_train, reference_buffers
from train.envs.config import PostEnvConfig
from train.envs.cpu.vec_env import PostTrainEnv
from train.episodes import load_episodes
from train.policy import load_policy
from train.rl_model import InteractionActor


@pytest.fixture(scope="module")
def bc_policy(bc_corpus):
    """The default corpus (``train``) and a BC policy trained on it briefly: the policy's path."""
    return bc_corpus[1]


SMOKE = PostTrainConfig(iterations=1, steps_per_env=6, env=PostEnvConfig(envs=2), disc_minibatches=2, critic_warmup=0)


def test_the_actor_starts_as_the_bc_policy_and_is_plugged_by_name(bc_policy):
    """rsl_rl resolves the actor by its class name; its mean action is the BC policy's on the same windows."""
    from rsl_rl.utils import resolve_callable

    env = PostTrainEnv(load_episodes("train"), 5, PostEnvConfig(envs=2))
    obs = env.get_observations()
    cls = resolve_callable("train.rl_model:InteractionActor")
    actor = cls(obs, {"actor": ["policy"]}, "actor", 29, str(bc_policy))
    assert cls is InteractionActor
    policy = load_policy(bc_policy)
    h = {k: torch.as_tensor(v, dtype=torch.float32) for k, v in env.history.terms.items()}
    with torch.no_grad():
        mean = actor(obs)
        sample = actor(obs, stochastic_output=True)
    torch.testing.assert_close(mean, policy.act(h["proprio"], h["root_command"], h["df"]), rtol=0, atol=1e-6)
    assert 0 < float((sample - mean).abs().mean()) < 0.2  # init_std 0.1 rad
    with pytest.raises(ValueError, match="the policy reads"):
        cls(obs, {"actor": ["critic"]}, "actor", 29, str(bc_policy))


def test_the_environment_restarts_episodes_and_hands_the_priors_their_inputs(bc_policy):
    env = PostTrainEnv(load_episodes("train"), 5, PostEnvConfig(envs=2, seed=3))
    scales = [s.scale for s in env.env.slots]
    assert all(0.4 <= v <= 1.6 for s in scales for v in s) and len({tuple(s) for s in scales}) == 2
    hold = torch.as_tensor(np.stack([s.data.qpos[7:36] for s in env.env.slots]), dtype=torch.float32)
    before = env.history.terms["proprio"][:, -1, AMP_STATE].copy()
    obs, reward, done, extras = env.step(hold)
    transition = extras["style"]["transition"].numpy()
    np.testing.assert_allclose(transition[:, :64], before, atol=1e-6)
    np.testing.assert_allclose(transition[:, 64:], env.history.terms["proprio"][:, -1, AMP_STATE], atol=1e-5)
    assert obs["policy"].shape == (2, 5 * (93 + 12 + env.history.terms["df"].shape[-1]))
    assert reward.shape == (2,) and torch.isfinite(reward).all() and not done.any()
    assert extras["log"]["/reward/termination"] == 0.0 and extras["log"]["/reward/action_rate"] == 0.0  # first step
    _, _, _, extras = env.step(hold + 0.01)  # the policy's targets, before the actuation noise
    assert extras["log"]["/reward/action_rate"] == pytest.approx(29 * 0.01**2, rel=1e-4)
    env.env.slots[0].done = True  # an episode that ends is restarted at once with a new draw
    first = env.env.slots[0]
    env.step(hold)
    assert env.env.slots[0] is not first and env.episode_length_buf[0] == 0
    for _ in range(3):  # every restart draws a new scale: the fields of the old ones are dropped
        env.env.slots[0].done = True
        env.step(hold)
    assert set(env.env._fields) == set().union(*(s.field_keys for s in env.env.slots))


def test_one_ppo_iteration_from_a_bc_checkpoint_trains_the_policy_and_both_priors(bc_policy, tmp_path):
    refs = reference_buffers("train", load_policy(bc_policy).vae)
    assert refs["aip"].shape[1] == 64 and refs["amp"].shape[1] == 128 and len(refs["amp"]) < len(refs["aip"])
    row = post_train("train", bc_policy, tmp_path, SMOKE)
    assert row["iteration"] == 0 and row["env_steps"] == 12 and row["seconds"] > 0
    for prior in ("aip", "amp"):
        assert 0 <= row[f"{prior}_reward"] <= 1 and row[f"{prior}_lsgan"] > 0 and row[f"{prior}_grad_penalty"] >= 0
    assert np.isfinite(row["value"]) and np.isfinite(row["surrogate"])
    before, after = load_policy(bc_policy), load_policy(tmp_path / "policy.pt")
    moved = [not torch.equal(a, b) for a, b in zip(before.backbone.parameters(), after.backbone.parameters())]
    assert any(moved)
    for a, b in zip(before.vae.parameters(), after.vae.parameters()):
        assert torch.equal(a, b)  # the VAE stays frozen
    for ckpt in ("policy.pt", "post_state.pt"):  # no class path of ours inside: moving a module never breaks a resume
        with zipfile.ZipFile(tmp_path / ckpt) as z:
            pickled = b"".join(z.read(n) for n in z.namelist() if n.endswith(".pkl"))
        assert b"train." not in pickled and b"pipeline." not in pickled, ckpt
    post_train("train", bc_policy, tmp_path, SMOKE)  # resumed: nothing left to do
    post_train("train", bc_policy, tmp_path, replace(SMOKE, iterations=2))
    rows = [json.loads(line) for line in (tmp_path / "post_log.jsonl").open()]
    assert [r["iteration"] for r in rows] == [0, 1]


def test_the_critic_warms_up_alone_at_its_own_rate(bc_policy):
    from train.aip import build, iteration

    env, alg = build("train", bc_policy, replace(SMOKE, critic_warmup=1))
    assert [g["lr"] for g in alg.optimizer.param_groups] == [SMOKE.ppo.learning_rate, SMOKE.critic_lr]
    actor, critic = [p.clone() for p in alg.actor.parameters()], [p.clone() for p in alg.critic.parameters()]
    alg.freeze_actor(True)
    iteration(env, alg, env.get_observations(), SMOKE.steps_per_env)
    assert all(torch.equal(a, b) for a, b in zip(actor, alg.actor.parameters()))
    assert any(not torch.equal(a, b) for a, b in zip(critic, alg.critic.parameters()))
    alg.freeze_actor(False)
    assert not any(p.requires_grad for p in alg.actor.policy.vae.parameters())  # the VAE stays frozen
    iteration(env, alg, env.get_observations(), SMOKE.steps_per_env)
    assert any(not torch.equal(a, b) for a, b in zip(actor, alg.actor.parameters()))
    env.close()


def test_ablations_drop_what_they_name_and_unknown_ones_are_refused(bc_policy, tmp_path, capsys):
    from lessmimic.cli import main
    from train.evaluation.table2 import EvalConfig, scale_line, scale_note

    row = post_train("train", bc_policy, tmp_path, replace(SMOKE, ablation="-AIP"))
    assert "aip_reward" not in row and "amp_reward" in row
    line = scale_line(scale_note("train", EvalConfig(), tmp_path / "policy.pt"))
    assert "post-trained 1 PPO iterations (12 env steps in 2 envs, ablation -AIP)" in line
    with pytest.raises(InputError, match="ablation: not a post-training ablation: '-Syn'; known: -AIP, -Rand"):
        PostTrainConfig(ablation="-Syn")
    capsys.readouterr()  # the progress bars so far
    assert main(["train-aip", "--name", "train", "--run", str(bc_policy.parent), "--ablation=-Foo"]) == 2
    assert main(["train-aip", "--name", "train", "--run", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "unknown ablation '-Foo'" in err[0] and "no BC + DAgger policy here" in err[1]


def test_an_episodes_variation_reaches_the_scene_the_initial_state_and_the_command(bc_policy):
    import mujoco

    from train.envs.cpu.env import InteractionEnv
    from train.mdp.randomize import Variation

    episode = next(e for e in load_episodes("train") if e.task == "PickUp")
    v = Variation(cylinder=True, mass_factor=1.5, friction_factor=0.5, restitution=0.2, robot_offset=(0.03, 0, 0),
                  command_offset=(0.05, 0, 0))  # fmt: skip
    env = InteractionEnv()
    plain = env.reset([(episode, 1.0)])
    base = env.slots[0]
    varied = env.reset([(episode, 1.0, v)])
    slot = env.slots[0]
    (name,) = slot.scene.object_body_id
    m, m0 = slot.scene.model, base.scene.model
    body, body0 = slot.scene.object_body_id[name], base.scene.object_body_id[name]
    geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] == body and m.geom_contype[g]]
    geoms0 = [g for g in range(m0.ngeom) if m0.geom_bodyid[g] == body0 and m0.geom_contype[g]]
    assert {m.geom_type[g] for g in geoms} == {mujoco.mjtGeom.mjGEOM_CYLINDER}
    assert {m0.geom_type[g] for g in geoms0} == {mujoco.mjtGeom.mjGEOM_BOX}
    assert m.body_mass[body] == pytest.approx(1.5 * m0.body_mass[body0])
    assert m.geom_friction[geoms[0], 0] == pytest.approx(0.5 * m0.geom_friction[geoms0[0], 0])
    assert m.geom_solref[geoms[0], 0] < 0 <= m0.geom_solref[geoms0[0], 0]  # restitution: a contact spring
    assert slot.data.qpos[0] - base.data.qpos[0] == pytest.approx(0.03)
    moved = np.linalg.norm(varied.root_command[0, :3] - plain.root_command[0, :3])
    assert moved == pytest.approx(0.02, abs=1e-9)  # the target 5 cm ahead, the robot 3 cm
