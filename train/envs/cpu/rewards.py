"""The CPU backend's task rewards: the terms of :mod:`train.mdp.rewards` on the environments' state after a step."""

from __future__ import annotations

import numpy as np

from pipeline.robot import NUM_JOINTS
from train.envs.cpu.env import InteractionEnv
from train.mdp import rewards as R


def task_rewards(env: InteractionEnv, actions: np.ndarray, last_actions: np.ndarray, weights: R.RewardWeights):
    """(N,) the weighted task terms after a step (``last_actions`` the targets of the step before, or the same
    ``actions`` on an episode's first step), and each term's mean (for the log)."""
    slots = env.slots
    root = np.stack([s.data.qpos[:3] for s in slots])
    ref_root = np.stack([s.episode.simulated.robot.qpos[min(s.t, s.episode.simulated.frames - 1), :3] for s in slots])
    obj = np.stack([s.last_facts.object_pos for s in slots])
    obj_ref = np.stack([s.last_facts.object_ref for s in slots])
    fell = np.array([s.fell for s in slots])
    m = slots[0].scene.model
    lower, upper = m.jnt_range[1 : 1 + NUM_JOINTS].T
    q = np.stack([s.data.qpos[7 : 7 + NUM_JOINTS] for s in slots])
    terms = {
        "root_tracking": R.root_tracking(root, ref_root),
        "object_tracking": R.object_tracking(obj, obj_ref, weights.object_sigma_m),
        "action_rate": R.action_rate(actions, last_actions),
        "termination": R.termination(fell, np.zeros_like(fell)),
        "joint_limits": R.joint_limits(q, lower, upper, weights.soft_limit),
    }
    return R.total(terms, weights), {k: float(np.mean(v)) for k, v in terms.items()}
