"""Who acts in the environment: the student policy (:class:`PolicyActor`, with its ``l``-step observation history)
or the QP teacher (:class:`TeacherActor`, the reference-based baseline). Both answer ``act(env) -> (N, 29)`` for
the environments still running, after ``reset(env)`` at the start of their episodes."""

from __future__ import annotations

import numpy as np
import torch

from pipeline.errors import InputError
from train.envs.cpu.env import EnvConfig, History, InteractionEnv, Obs
from train.teacher import Teacher, episode_reference


def check_profile(env: InteractionEnv, want: str) -> None:
    """Every environment's episode physicalized under the actuator profile ``want`` the policy acts for."""
    for s in env.slots:
        if s.episode.profile != want:
            raise InputError(
                s.episode.simulated.robot.source,
                "actuator_profile",
                f"episode physicalized under {s.episode.profile!r}, the policy acts for {want!r}",
            )


class PolicyActor:
    """A trained :class:`train.policy.InteractionPolicy` acting on its observation history."""

    def __init__(self, policy, device: str = "cpu"):
        self.policy, self.device = policy.eval(), device
        self.history = History(policy.config.history)

    def env_config(self, **kw) -> EnvConfig:
        """The environment that observes what the policy reads (its DF links and observation contract)."""
        return EnvConfig.for_policy(self.policy.layout, **kw)

    def reset(self, env: InteractionEnv) -> None:
        check_profile(env, self.policy.layout.actuator_profile)
        self.history.reset(env.observe())

    def observe(self, obs: Obs) -> None:
        self.history.push(obs)

    @torch.no_grad()
    def act(self, env: InteractionEnv) -> np.ndarray:
        h = self.history.terms
        tensors = [
            torch.as_tensor(h[k], dtype=torch.float32, device=self.device) for k in ("proprio", "root_command", "df")
        ]
        return self.policy.act(*tensors).cpu().numpy().astype(np.float64)


class TeacherActor:
    """The QP teacher of each environment's episode (its 1.0x feasible reference, under the episode's actuator
    profile), bound to that environment's (possibly scaled) model. References are built once per episode and reused."""

    def __init__(self):
        self.teachers: list[Teacher] = []
        self._refs: dict[int, object] = {}

    def env_config(self, **kw) -> EnvConfig:
        return EnvConfig(**kw)

    def reset(self, env: InteractionEnv) -> None:
        self.teachers = [self._teacher(s) for s in env.slots]

    def _teacher(self, slot) -> Teacher:
        """The teacher of ``slot``'s episode on its model, its reference built once per episode."""
        key = id(slot.episode)
        if key not in self._refs:
            self._refs[key] = episode_reference(slot.episode)
        return Teacher(slot.episode, slot.scene.model, ref=self._refs[key])

    def observe(self, obs: Obs) -> None:
        pass

    def rebind(self, env: InteractionEnv, i: int) -> None:
        """Environment ``i`` went on with another episode (a chain's next task): its teacher tracks that one."""
        self.teachers[i] = self._teacher(env.slots[i])

    def act(self, env: InteractionEnv) -> np.ndarray:
        out = np.zeros((env.num_envs, 29))
        for i, (s, teacher) in enumerate(zip(env.slots, self.teachers)):
            if not s.done:
                out[i] = teacher.act(s.data, s.t)
        return out
