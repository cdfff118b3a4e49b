"""Discriminative post-training (paper Sec. III-C, App. B): PPO from the BC + DAgger policy with two LSGAN style
priors. Read top to bottom:

1. :class:`AdversarialPPO` is rsl_rl's PPO plus the priors. After every environment step it adds the style rewards
   to the task reward, ``r = r_task + w_int r_interact + w_mot r_style`` with ``r = max(0, 1 - 0.25 (D - 1)^2)``:
   the **AIP** discriminator reads the interaction latent ``z = VAE.encode(u_t)`` of the state reached, the **AMP**
   discriminator the robot's state transition (:data:`pipeline.terms.layout.AMP_STATE`). After PPO's own update it
   trains
   each discriminator (:mod:`train.discriminator`, Eq. 4 with a gradient penalty) on the iteration's policy
   samples against its reference buffer, at the paper's 2e-4;
2. :func:`reference_buffers`: ``B_ref`` of the AIP is the VAE latents of every frame of the valid episodes of the
   features dataset (the pre-training data); the AMP's is their consecutive-frame transitions;
3. :func:`post_train` builds the restarting environment (:class:`train.envs.cpu.vec_env.PostTrainEnv` on the CPU, or
   :class:`train.envs.mjlab.env.MjlabPostTrainEnv` on a GPU with ``backend="mjlab"``; the six randomisations of
   :mod:`train.mdp.randomize`), the actor (:class:`train.rl_model.InteractionActor`, initialised
   from ``policy.pt``), an MLP critic (rsl_rl's, normalised inputs), and runs ``iterations`` of:
   ``steps_per_env`` steps of rollout, returns (GAE), PPO update, discriminator update; a row of
   ``post_log.jsonl`` per iteration, and ``policy.pt`` (an interaction-policy checkpoint that ``lessmimic eval``
   scores like any other) after each.

Ablations (:mod:`train.ablation`): ``-AIP`` drops the interaction prior, ``-Rand`` every randomisation
(:mod:`train.mdp.randomize`); ``-Syn`` and ``-Trans`` post-train their own pre-training run in the same way.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
from rsl_rl.algorithms import PPO
from rsl_rl.env import VecEnv
from rsl_rl.models import MLPModel
from rsl_rl.storage import RolloutStorage
from tqdm import tqdm

from pipeline.dataset.read import episode_ranges, read_columns
from pipeline.errors import InputError
from pipeline.stage.atomic import write_json_atomic, write_torch_atomic
from pipeline.stage.paths import stage_dir
from pipeline.terms.layout import AMP_STATE, DF, PROPRIO
from train.ablation import POST_TRAINING
from train.discriminator import Discriminator, DiscriminatorConfig
from train.envs.config import PostEnvConfig
from train.envs.cpu.vec_env import PostTrainEnv
from train.episodes import load_episodes
from train.mdp.randomize import RandomizationConfig
from train.mdp.rewards import RewardWeights, lsgan_reward
from train.policy import load_policy, save_policy
from train.rl_model import InteractionActor
from train.vae import DFVAE

BACKENDS = ("cpu", "mjlab")
"""Where the environments step: native MuJoCo on the CPU (:mod:`train.envs.cpu.vec_env`) or mjlab's MuJoCo Warp on a GPU
(:mod:`train.envs.mjlab.env`, the paper's scale)."""


@dataclass(frozen=True)
class PPOConfig:
    """rsl_rl PPO's settings; ``gamma`` and ``entropy_coef`` are the paper's. The actor's learning rate is fixed at
    5e-7, not the paper's 1e-3 under rsl_rl's adaptive-KL schedule: measured on the laptop run's BC + DAgger
    Transformer at exploration std 0.05 rad, one update's 20 Adam steps move the policy by a mean KL of 2.2 at lr
    1e-5, 0.040 at 1e-6, 0.010 at 5e-7 (the schedule's target) and 0.003 at 2.5e-7. The adaptive schedule's floor is
    1e-5, so it sat there for all 87 iterations of a first run, every update ~100x past its KL target."""

    learning_rate: float = 5e-7
    schedule: str = "fixed"
    gamma: float = 0.99
    lam: float = 0.95
    entropy_coef: float = 5e-4
    clip_param: float = 0.2
    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    desired_kl: float = 0.01
    max_grad_norm: float = 1.0


@dataclass(frozen=True)
class PostTrainConfig:
    """``iterations`` of ``steps_per_env`` steps in ``env.envs`` environments; ``init_std`` the actor's exploration
    noise (rad); ``disc_minibatches``: each prior makes one pass per iteration over the iteration's policy samples
    in that many minibatches, each against as many reference samples drawn at random (so its cost follows the
    rollout's size, as PPO's own update does); ``ablation`` one of :data:`train.ablation.POST_TRAINING` or empty.

    The critic starts from scratch and learns at its own ``critic_lr`` (rsl_rl gives actor and critic one rate: at
    the actor's 1e-6 an Adam step moves a weight by ~1e-6, and the first laptop run's critic never fitted returns of
    a few hundred, its value loss still ~6e3 after 600 iterations, so the advantages were the returns themselves);
    for the first ``critic_warmup`` iterations only the critic and the priors learn, the actor stays the BC + DAgger
    policy.

    ``init_std`` is 0.05 rad: the pre-trained policy is only just balanced, and white noise on all 29 targets topples
    it. Falls in 2400 steps (8 environments x 300) of the laptop run's policy under the randomisations: 9 without
    noise, 13 / 14 / 16 at 0.02 / 0.03 / 0.05 rad, 31 at 0.1 (without the randomisations: 5 at 0.02, 30 at 0.1); at
    0.1 nearly every episode ended in a fall within ~80 steps, before any lift or sit the reward could teach."""

    iterations: int = 600
    steps_per_env: int = 24
    env: PostEnvConfig = field(default_factory=PostEnvConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    disc: DiscriminatorConfig = field(default_factory=DiscriminatorConfig)
    disc_minibatches: int = 4
    init_std: float = 0.05
    critic_lr: float = 1e-3
    critic_warmup: int = 50
    ablation: str = ""
    seed: int = 0
    backend: str = "cpu"

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise InputError(None, "backend", f"unknown backend {self.backend!r}; known: {', '.join(BACKENDS)}")
        if self.ablation and self.ablation not in POST_TRAINING:
            why = f"not a post-training ablation: {self.ablation!r}; known: {', '.join(POST_TRAINING)}"
            raise InputError(None, "ablation", why)


class AdversarialPPO(PPO):
    """PPO whose reward gains the style priors' rewards and whose update also trains the priors (module docstring).
    ``priors`` maps ``"aip"`` / ``"amp"`` to ``(discriminator, reference buffer)``; ``vae`` encodes the AIP's z;
    ``disc_minibatches`` per prior and iteration (:class:`PostTrainConfig`)."""

    def __init__(self, actor, critic, storage, *, priors: dict, vae: DFVAE, weights: RewardWeights,
                 disc_minibatches: int, critic_lr: float, **ppo) -> None:  # fmt: skip
        super().__init__(actor, critic, storage, **ppo)
        self.optimizer = torch.optim.Adam(
            [{"params": actor.parameters(), "lr": self.learning_rate}, {"params": critic.parameters(), "lr": critic_lr}]
        )  # the "fixed" schedule never rewrites the groups' rates
        self.actor_trainable = [p for p in actor.parameters() if p.requires_grad]  # not the frozen VAE
        self.priors, self.vae, self.disc_minibatches = priors, vae, disc_minibatches
        self.style_weight = {"aip": weights.interaction_style, "amp": weights.motion_style}
        self.disc_optim = {k: torch.optim.Adam(d.parameters(), lr=d.config.lr) for k, (d, _) in priors.items()}
        self.samples: dict[str, list[torch.Tensor]] = {k: [] for k in priors}
        self.style_rewards: dict[str, list[float]] = {k: [] for k in priors}  # per step, for the log

    def freeze_actor(self, frozen: bool) -> None:
        """Hold the actor (its mean and its exploration noise) while the critic warms up."""
        for p in self.actor_trainable:
            p.requires_grad_(not frozen)

    def style_inputs(self, style: dict) -> dict[str, torch.Tensor]:
        """What each prior reads from the environment's ``extras["style"]``."""
        read = {"aip": lambda: self.vae.encode(style["df"]), "amp": lambda: style["transition"]}
        return {k: read[k]() for k in self.priors}

    def process_env_step(self, obs, rewards, dones, extras) -> None:
        inputs = self.style_inputs(extras["style"])
        total = rewards.clone()
        for name, (disc, _) in self.priors.items():
            r = lsgan_reward(disc(inputs[name]))
            total += self.style_weight[name] * r
            self.samples[name].append(inputs[name])
            self.style_rewards[name].append(float(r.mean()))
        super().process_env_step(obs, total, dones, extras)

    def update(self) -> dict[str, float]:
        losses = super().update()
        for name, (disc, reference) in self.priors.items():
            policy = torch.cat(self.samples[name]).clone()  # out of inference mode
            self.samples[name] = []
            for rows in torch.randperm(len(policy)).chunk(self.disc_minibatches):
                ref = reference[torch.randint(len(reference), (len(rows),))]
                loss, parts = disc.loss(ref, policy[rows])
                self.disc_optim[name].zero_grad()
                loss.backward()
                self.disc_optim[name].step()
            losses |= {f"{name}_{k}": v for k, v in parts.items()}
            losses[f"{name}_reward"] = float(np.mean(self.style_rewards[name]))  # over the iteration's steps
            self.style_rewards[name] = []
        return losses


def reference_buffers(name: str, vae: DFVAE) -> dict[str, torch.Tensor]:
    """``{"aip": (F, latent), "amp": (F - E, 2 x 64)}`` from the valid episodes of corpus ``name``'s features
    dataset (module docstring)."""
    root = stage_dir(name, "features")
    episodes = load_episodes(name, valid_only=False)
    cols = {k: np.array(v) for k, v in read_columns(root, [DF, PROPRIO]).items()}  # writable
    starts, ends, _ = episode_ranges(root)
    latents, transitions = [], []
    for e, a, b in zip(episodes, starts, ends):
        if not e.simulated.validation.get("valid", False):
            continue
        with torch.no_grad():
            latents.append(vae.encode(torch.as_tensor(cols[DF][a:b], dtype=torch.float32)))
        s = cols[PROPRIO][a:b, AMP_STATE]
        transitions.append(torch.as_tensor(np.concatenate([s[:-1], s[1:]], axis=1), dtype=torch.float32))
    if not latents:
        raise InputError(root, "validation.valid", "no valid episode to build the reference buffers from")
    return {"aip": torch.cat(latents), "amp": torch.cat(transitions)}


def _save_state(alg: AdversarialPPO, iteration: int, path: Path) -> None:
    state = alg.save() | {
        "iteration": iteration,
        "priors": {k: d.state_dict() for k, (d, _) in alg.priors.items()},
        "prior_optimizers": {k: o.state_dict() for k, o in alg.disc_optim.items()},
        "torch_rng": torch.get_rng_state(),
    }
    write_torch_atomic(path, state)


def build(name: str, policy_path: str | Path, config: PostTrainConfig, device: str = "cpu",
          priors: tuple[str, ...] = ("aip", "amp")) -> tuple[VecEnv, AdversarialPPO]:  # fmt: skip
    """The environment and the algorithm of :func:`post_train` (module docstring, step 3) with the style ``priors``
    named (none: plain PPO); ``config.ablation`` "-Rand" switches the randomisations off."""
    torch.manual_seed(config.seed)
    env_cfg = replace(config.env, seed=config.seed)
    if config.ablation == "-Rand":
        env_cfg = replace(env_cfg, randomization=RandomizationConfig.off())
    layout = load_policy(policy_path).layout
    if layout.contract != "lessmimic":  # the priors and both backends observe the paper's contract
        raise InputError(policy_path, "layout.contract", f"{layout.contract!r}: post-training reads 'lessmimic' only")
    history = layout.history
    if config.backend == "mjlab":
        from train.envs.mjlab.env import MjlabPostTrainEnv, runnable_episodes

        env = MjlabPostTrainEnv(runnable_episodes(load_episodes(name)), history, env_cfg, device)
    else:
        env = PostTrainEnv(load_episodes(name), history, env_cfg, device)
    obs = env.get_observations()
    groups = {"actor": ["policy"], "critic": ["critic"]}
    actor = InteractionActor(obs, groups, "actor", env.num_actions, str(policy_path), init_std=config.init_std)
    critic = MLPModel(obs, groups, "critic", 1, hidden_dims=(256, 256, 128), activation="elu", obs_normalization=True)
    storage = RolloutStorage("rl", env.num_envs, config.steps_per_env, obs, [env.num_actions], device)
    vae = actor.policy.vae
    refs = reference_buffers(name, vae) if priors else {}
    discs = {k: (Discriminator(refs[k], config.disc).to(device), refs[k].to(device)) for k in priors}
    alg = AdversarialPPO(actor, critic, storage, priors=discs, vae=vae, weights=env_cfg.weights,
                         disc_minibatches=config.disc_minibatches, critic_lr=config.critic_lr, device=device,
                         **asdict(config.ppo))  # fmt: skip
    return env, alg


def iteration(env: VecEnv, alg: AdversarialPPO, obs, steps: int) -> tuple[object, dict]:
    """One PPO iteration: ``steps`` rollout steps in every environment, the returns, the update. The next
    observation and the iteration's figures (task reward, falls, the reward terms' means, the losses)."""
    alg.train_mode()
    returns, falls, logs = [], 0, []
    with torch.inference_mode():
        for _ in range(steps):
            obs, reward, done, extras = env.step(alg.act(obs))
            alg.process_env_step(obs, reward, done, extras)
            returns.append(float(reward.mean()))
            falls += int((done & ~extras["time_outs"]).sum())
            logs.append(extras["log"])
        alg.compute_returns(obs)
    losses = alg.update()
    figures = {
        "task_reward": float(np.mean(returns)),
        "falls": falls,
        **{k.strip("/").replace("/", "."): float(np.mean([g[k] for g in logs])) for k in logs[0]},
        **losses,
        "learning_rate": alg.learning_rate,
        "action_std": float(alg.actor.distribution.log_std_param.detach().exp().mean()),
    }
    return obs, figures


def post_train(name: str, policy_path: str | Path, out_dir: str | Path, config: PostTrainConfig = PostTrainConfig(),
               device: str = "cpu") -> dict:  # fmt: skip
    """Post-train the policy at ``policy_path`` on corpus ``name`` into ``out_dir`` (module docstring); resumes after
    the last finished iteration. Returns the last log row."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    priors = ("amp",) if config.ablation == "-AIP" else ("aip", "amp")
    env, alg = build(name, policy_path, config, device, priors)
    state_path, log_path = out_dir / "post_state.pt", out_dir / "post_log.jsonl"
    start = 0
    if state_path.is_file():
        state = torch.load(state_path, map_location=device, weights_only=False)
        alg.load(state, None, strict=True)
        for k, (d, _) in alg.priors.items():
            d.load_state_dict(state["priors"][k])
            alg.disc_optim[k].load_state_dict(state["prior_optimizers"][k])
        torch.set_rng_state(state["torch_rng"])
        start = state["iteration"] + 1
    obs, row = env.get_observations(), {}
    for it in tqdm(range(start, config.iterations), desc="post-train", unit="iteration"):
        t0 = time.perf_counter()
        alg.freeze_actor(it < config.critic_warmup)
        obs, figures = iteration(env, alg, obs, config.steps_per_env)
        steps = (it + 1) * config.steps_per_env * env.num_envs
        row = {"iteration": it, "env_steps": steps, **figures, "seconds": time.perf_counter() - t0}
        save_policy(alg.actor.policy, out_dir / "policy.pt", post_train_config=_jsonable(asdict(config)))
        _save_state(alg, it, state_path)
        with log_path.open("a", encoding="utf-8") as f:
            f.write(json.dumps(row) + "\n")
    env.close()
    _report(policy_path, out_dir, config, row)
    return row


def _report(policy_path: str | Path, out_dir: Path, config: PostTrainConfig, row: dict) -> None:
    """``out_dir/report.json``: the pre-training run's scale (its ``report.json``) with the post-training's added,
    so an evaluation of ``out_dir/policy.pt`` says both."""
    pre = Path(policy_path).parent / "report.json"
    scale = json.loads(pre.read_text()).get("scale", {}) if pre.is_file() else {}
    post = {
        "iterations": row.get("iteration", -1) + 1,
        "env_steps": row.get("env_steps", 0),
        "envs": config.env.envs,
        "steps_per_env": config.steps_per_env,
        "ablation": config.ablation or "none",
        "backend": config.backend,
        "from": str(policy_path),
    }
    write_json_atomic(out_dir / "report.json", {"scale": {**scale, "post_training": post}})


def _jsonable(d: dict) -> dict:
    return json.loads(json.dumps(d, default=list))
