"""The interaction environment as rsl_rl's :class:`~rsl_rl.env.VecEnv` for post-training (paper Sec. III-C): ``N``
environments that never stop (a finished episode restarts at once with a new draw), the policy's observation
history, and the task rewards of the paper's table (:mod:`train.mdp.rewards`) measured after every step.

* **Episodes**: each start draws a training episode uniformly and its randomisations (:mod:`train.mdp.randomize`:
  object scale per axis and shape, physical properties, initial offsets, command offset); every step adds the
  actuation noise to the joint targets and the perception noise to the DF features the policy reads. The paper
  post-trains on procedurally varied objects, while BC + DAgger only saw scale 1.0.
* **Observations** (a TensorDict): ``policy``, the flat ``l``-step windows :class:`train.rl_model.InteractionActor`
  reads (:meth:`pipeline.terms.layout.ObservationLayout.flatten`); ``critic``, the current step's ``[proprio,
  root_command, df]``.
* **Rewards** after the step, before any restart: root tracking against the episode's simulated root at its time,
  object tracking against the object's reference track, the action rate, the termination (a fall, not a
  time-out) and the soft joint limits (:func:`train.envs.cpu.rewards.task_rewards`); the action rate compares the
  policy's targets
  (before the actuation noise) and is 0 on an episode's first step. The style rewards (AIP, AMP) are the algorithm's
  (:class:`train.aip.AdversarialPPO`): ``extras["style"]`` carries what they read, taken before any restart: the DF
  features ``df`` (N, 10K) of the state reached and the AMP transition ``(s_t, s_(t+1))`` (N, 2 x 64) with ``s`` the
  proprioception without the previous action (:data:`pipeline.terms.layout.AMP_STATE`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from pipeline.robot import NUM_JOINTS
from pipeline.terms.layout import AMP_STATE, ObservationLayout
from train.envs.config import PostEnvConfig
from train.envs.cpu.env import EnvConfig, History, InteractionEnv, Obs
from train.envs.cpu.rewards import task_rewards
from train.episodes import Episode
from train.mdp.randomize import Variation, actuation_noise, draw, perception_noise


class PostTrainEnv(VecEnv):
    """``config.envs`` restarting environments over ``episodes`` for a policy with an ``history``-step window."""

    def __init__(self, episodes: list[Episode], history: int, config: PostEnvConfig = PostEnvConfig(), device="cpu"):
        if not episodes:
            raise ValueError("post-training needs at least one episode")
        self.episodes, self.config, self.cfg, self.device = episodes, config, config, torch.device(device)
        self.rng = np.random.default_rng([config.seed, 7])
        self.env = InteractionEnv(EnvConfig(threads=config.threads))
        self.history = History(history)
        self.layout = ObservationLayout(self.env.cfg.links, history)
        self.history.reset(self._seen(self.env.reset([self._draw() for _ in range(config.envs)])))
        self.last_actions = np.stack([s.last_action for s in self.env.slots])
        self.num_envs, self.num_actions = config.envs, NUM_JOINTS
        self.max_episode_length = max(e.simulated.frames for e in episodes)
        self.episode_length_buf = torch.zeros(config.envs, dtype=torch.long, device=self.device)

    def _draw(self) -> tuple[Episode, tuple, Variation]:
        v = draw(self.config.randomization, self.rng)
        return self.episodes[self.rng.integers(len(self.episodes))], v.scale, v

    def _seen(self, obs: Obs) -> Obs:
        """What the policy sees: the DF features with the perception noise."""
        return replace(obs, df=perception_noise(obs.df, self.config.randomization.df_noise, self.rng))

    def _tensor(self, x: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(x, dtype=torch.float32, device=self.device)

    def get_observations(self) -> TensorDict:
        h = self.history.terms
        current = np.concatenate([h["proprio"][:, -1], h["root_command"][:, -1], h["df"][:, -1]], axis=1)
        return TensorDict(
            {
                "policy": self._tensor(self.layout.flatten(h["proprio"], h["root_command"], h["df"])),
                "critic": self._tensor(current),
            },
            batch_size=[self.num_envs],
        )

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Step every environment with raw joint targets ``actions`` (N, 29); restart the finished ones."""
        a = actions.detach().cpu().numpy().astype(np.float64)
        first = np.array([s.t == 0 for s in self.env.slots])
        last = np.where(first[:, None], a, self.last_actions)
        self.last_actions = a
        before = self.history.terms["proprio"][:, -1, AMP_STATE].copy()  # proprio carries no perception noise
        obs, done = self.env.step(actuation_noise(a, self.config.randomization.action_noise_rad, self.rng))
        reward, means = task_rewards(self.env, a, last, self.config.weights)
        fell = np.array([s.fell for s in self.env.slots])
        style = {
            "df": self._tensor(obs.df),
            "transition": self._tensor(np.concatenate([before, obs.proprio[:, AMP_STATE]], axis=1)),
        }
        self.history.push(self._seen(obs))
        self.episode_length_buf += 1
        if done.any():
            for i in np.flatnonzero(done):
                self.env.reset_one(i, *self._draw())
            self.history.reset(self._seen(self.env.observe()), which=done)
            self.episode_length_buf[torch.as_tensor(done, device=self.device)] = 0
        extras = {
            "time_outs": torch.as_tensor(done & ~fell, device=self.device),
            "style": style,
            "log": {f"/reward/{k}": v for k, v in means.items()},
        }
        return self.get_observations(), self._tensor(reward), torch.as_tensor(done, device=self.device), extras

    def close(self) -> None:
        self.env.close()
