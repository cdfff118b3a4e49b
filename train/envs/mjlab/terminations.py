"""The mjlab backend's terminations: the fall test of :mod:`pipeline.terms.fall` per world, and the reference's
end (a time-out)."""

from __future__ import annotations

import torch
from mjlab.envs import ManagerBasedRlEnv

from pipeline.terms.fall import FALL_HEIGHT_DROP, FALL_TILT_COS
from train.envs.mjlab.worlds import Worlds, robot_state


def fell(env: ManagerBasedRlEnv, worlds: Worlds) -> torch.Tensor:
    """:func:`pipeline.terms.fall.fallen` per world: the pelvis too low or the torso tilted from the reference's."""
    e, k = worlds.index(env)
    up = env.sim.data.xmat[:, worlds.bodies(env, ("torso_link",))[0]].reshape(-1, 3, 3)[:, :, 2]
    low = robot_state(env)[0][:, 2] < worlds.qpos[e, k, 2] - FALL_HEIGHT_DROP
    return low | ((up * worlds.torso_up[e, k]).sum(-1) < FALL_TILT_COS)


def reference_end(env: ManagerBasedRlEnv, worlds: Worlds) -> torch.Tensor:
    return env.episode_length_buf >= worlds.frames[worlds.episode] - 1
