"""The mjlab backend's action: absolute joint position targets with the actuation noise."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from mjlab.envs import ManagerBasedRlEnv
from mjlab.envs.mdp.actions import JointPositionAction, JointPositionActionCfg

from train.envs.mjlab.worlds import Worlds
from train.mdp.randomize import actuation_noise


class NoisyJointTargets(JointPositionAction):
    """mjlab's joint-position action with the actuation noise (:func:`train.mdp.randomize.actuation_noise`)."""

    def process_actions(self, actions: torch.Tensor) -> None:
        super().process_actions(actuation_noise(actions, self.cfg.sigma, self.cfg.worlds.torch_rng))


@dataclass(kw_only=True)
class NoisyJointTargetsCfg(JointPositionActionCfg):
    """Absolute joint targets (scale 1, no offset) with Gaussian noise ``sigma`` [rad] from ``worlds``' generator."""

    scale: float = 1.0
    use_default_offset: bool = False
    sigma: float = 0.0
    worlds: Worlds | None = None

    def build(self, env: ManagerBasedRlEnv) -> NoisyJointTargets:
        return NoisyJointTargets(self, env)
