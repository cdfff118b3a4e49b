"""What a post-training environment is, on either backend: how many environments, the randomisation ranges, the
reward weights and the seed of the draws."""

from __future__ import annotations

from dataclasses import dataclass, field

from train.mdp.randomize import RandomizationConfig
from train.mdp.rewards import RewardWeights


@dataclass(frozen=True)
class PostEnvConfig:
    """``envs`` environments stepped in ``threads`` threads (the CPU backend's); the ``randomization`` ranges; the
    reward ``weights``; ``seed`` of the draws."""

    envs: int = 8
    threads: int = 1
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)
    weights: RewardWeights = field(default_factory=RewardWeights)
    seed: int = 0
