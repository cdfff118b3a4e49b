"""The mjlab backend's reward terms: the task terms of :mod:`train.mdp.rewards` on the worlds' state."""

from __future__ import annotations

import torch
from mjlab.envs import ManagerBasedRlEnv

from pipeline.robot import NQ_ROBOT
from train.envs.mjlab.worlds import Worlds, robot_state
from train.mdp import rewards as R


def root_tracking(env: ManagerBasedRlEnv, worlds: Worlds) -> torch.Tensor:
    e, k = worlds.index(env)
    return R.root_tracking(robot_state(env)[0][:, :3], worlds.qpos[e, k, :3])


def object_tracking(env: ManagerBasedRlEnv, worlds: Worlds, sigma: float) -> torch.Tensor:
    e, k = worlds.index(env)
    target = worlds.object[e, k, :3].clone()
    target[:, 2] += worlds.dz  # the track raised as the first pose (Worlds.start)
    return R.object_tracking(env.sim.data.qpos[:, NQ_ROBOT : NQ_ROBOT + 3], target, sigma)


def action_rate(env: ManagerBasedRlEnv) -> torch.Tensor:
    """The policy's targets against the step before's; 0 on an episode's first step (as the CPU environment)."""
    a, last = env.action_manager.action, env.action_manager.prev_action
    return torch.where(env.episode_length_buf <= 1, 0.0, R.action_rate(a, last))


def termination(env: ManagerBasedRlEnv) -> torch.Tensor:
    m = env.termination_manager
    return R.termination(m.terminated, m.time_outs)


def joint_limits(env: ManagerBasedRlEnv, worlds: Worlds, soft: float) -> torch.Tensor:
    lower, upper = worlds.joint_limits
    return R.joint_limits(robot_state(env)[0][:, 7:], lower, upper, soft)
