"""The vision student acting in the interaction environment (:class:`VisionActor`): the evaluation's and the
distillation's actor interface (``env_config``, ``reset(env)``, ``observe(obs)``, ``act(env)``) with a depth sensor
per environment (:class:`train.vision.noise.DepthSensor`) read after every step.

SitStand is not scored for a vision policy (:attr:`VisionActor.excluded_tasks`): the seat is behind the robot, out of
the egocentric camera's view, as the paper excludes it (Sec. IV "Distilling to Visual Input").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from train.actors import check_profile
from train.envs.cpu.env import EnvConfig, History, InteractionEnv, Obs
from train.vision.noise import DepthNoise, DepthSensor

EXCLUDED_REASON = "not applicable to vision: the seat is behind the robot, outside the egocentric camera's view"


@dataclass
class VisionObs(Obs):
    """The environment's observation with each environment's depth frame ``(N, H, W)`` [m] (what the sensor returns
    this step: noise, latency and all)."""

    depth: np.ndarray


class DepthSensors:
    """One :class:`DepthSensor` per environment of the current batch, drawn from one generator."""

    def __init__(self, camera, noise: DepthNoise, seed: int | np.random.Generator = 0):
        self.camera, self.noise = camera, noise
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self.sensors: list[DepthSensor] = []

    def reset(self, env: InteractionEnv) -> None:
        self.sensors = [DepthSensor(self.camera, self.noise, self.rng) for _ in env.slots]
        for s in self.sensors:
            s.reset()

    def read(self, env: InteractionEnv) -> np.ndarray:
        """``(N, H, W)`` this step's frames."""
        return np.stack([sensor.read(s.scene.model, s.data) for sensor, s in zip(self.sensors, env.slots)])

    def observe(self, env: InteractionEnv, obs: Obs) -> VisionObs:
        return VisionObs(**vars(obs), depth=self.read(env))


class VisionActor:
    """A :class:`train.vision.student.VisionPolicy` acting on its windows of proprioception, root command and depth;
    ``noise``: the sensor model it sees (default: the training randomisation's, :class:`DepthNoise`), drawn from
    ``seed``."""

    excluded_tasks = ("SitStand",)
    excluded_reason = EXCLUDED_REASON

    def __init__(self, policy, noise: DepthNoise | None = None, seed: int | np.random.Generator = 0, device="cpu"):
        self.policy, self.device = policy.eval(), device
        self.sensors = DepthSensors(policy.camera, DepthNoise() if noise is None else noise, seed)
        self.history = History(policy.config.history)

    def env_config(self, **kw) -> EnvConfig:
        return EnvConfig.for_policy(self.policy.layout, **kw)

    def reset(self, env: InteractionEnv) -> None:
        check_profile(env, self.policy.layout.actuator_profile)
        self._env = env  # observe() reads this environment's cameras
        self.sensors.reset(env)
        self.history.reset(self.sensors.observe(env, env.observe()))

    def observe(self, obs: Obs) -> None:
        self.history.push(self.sensors.observe(self._env, obs))

    @torch.no_grad()
    def act(self, env: InteractionEnv) -> np.ndarray:
        terms = {k: torch.as_tensor(v, dtype=torch.float32, device=self.device) for k, v in self.history.terms.items()}
        return self.policy.act_observation(terms).cpu().numpy().astype(np.float64)
