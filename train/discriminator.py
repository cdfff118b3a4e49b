"""The least-squares GAN discriminator of the two style priors (paper App. B, Eq. 4; AMP, Peng et al. 2021):

* **AIP** (adversarial interaction prior) reads the DF interaction latent ``z_t`` (the VAE's mean, 64): reference
  samples from the pre-training data's latents (``B_ref``), policy samples from post-training rollouts at
  randomised object geometries;
* **AMP** reads robot state transitions ``(s_t, s_(t+1))`` from the physicalized dataset against the policy's.

Loss (Eq. 4): ``L_D = E_ref[(D(x) - 1)^2] + E_pi[(D(x) + 1)^2] + w_gp E_ref[||grad_x D(x)||^2]``. The gradient
penalty on the reference samples is the one HDMI and PhysHSI add to this LSGAN form (FIELD-NOTES): without it the
discriminator separates the two sets with a steep boundary and its reward saturates to 0 for every policy sample,
which gives PPO no gradient; ``gp_weight`` 0 removes it. Reward: ``max(0, 1 - 0.25 (D(x) - 1)^2)``
(:func:`train.mdp.rewards.lsgan_reward`). Inputs are standardised by the reference buffer's statistics, stored with
the weights.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from train.mdp.rewards import lsgan_reward
from train.normalize import Normalizer
from train.vae import mlp


@dataclass(frozen=True)
class DiscriminatorConfig:
    """``hidden`` ReLU layer widths; ``gp_weight`` of the gradient penalty; Adam ``lr`` (the paper's 2e-4)."""

    hidden: tuple[int, ...] = (1024, 512)
    gp_weight: float = 5.0
    lr: float = 2e-4


class Discriminator(nn.Module):
    """``D(x)``: standardise ``x`` by the reference buffer's statistics, then an MLP to one score."""

    def __init__(self, reference: torch.Tensor, config: DiscriminatorConfig = DiscriminatorConfig()):
        super().__init__()
        if reference.ndim != 2 or len(reference) < 2:
            raise ValueError(f"the reference buffer must be (N >= 2, D) samples, got {tuple(reference.shape)}")
        self.config = config
        self.norm = Normalizer.from_array(reference)
        self.net = mlp((reference.shape[1], *config.hidden, 1))

    @property
    def dim(self) -> int:
        return self.norm.dim

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N,) scores of samples ``x`` (N, D)."""
        if x.shape[-1] != self.dim:
            raise ValueError(f"the discriminator reads {self.dim}-d samples, got {x.shape[-1]}")
        return self.net(self.norm.normalize(x)).squeeze(-1)

    def loss(self, reference: torch.Tensor, policy: torch.Tensor) -> tuple[torch.Tensor, dict]:
        """``L_D`` (module docstring) on a batch of reference and policy samples, and its parts as floats."""
        ref = reference.detach().requires_grad_(True)
        d_ref, d_pol = self(ref), self(policy.detach())
        fit = ((d_ref - 1.0) ** 2).mean() + ((d_pol + 1.0) ** 2).mean()
        loss, gp = fit, torch.zeros(())
        if self.config.gp_weight > 0:
            (grad,) = torch.autograd.grad(d_ref.sum(), ref, create_graph=True)
            gp = grad.pow(2).sum(-1).mean()
            loss = fit + self.config.gp_weight * gp
        parts = {
            "lsgan": fit.item(),
            "grad_penalty": gp.item(),
            "d_ref": d_ref.mean().item(),
            "d_pol": d_pol.mean().item(),
        }
        return loss, parts

    @torch.no_grad()
    def reward(self, x: torch.Tensor) -> torch.Tensor:
        """(N,) the style reward of samples ``x``: ``max(0, 1 - 0.25 (D(x) - 1)^2)``."""
        return lsgan_reward(self(x))
