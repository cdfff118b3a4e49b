"""The BC + DAgger policy as an rsl_rl actor: ``class_name="train.rl_model:InteractionActor"`` plugs it into
rsl_rl's PPO (5.4.2 has MLP, CNN and RNN models only; a model class is resolved by name, as mjlab does for its CNN).

The actor reads the ``policy`` observation group, one flat row per environment holding the ``l``-step windows
``[proprio (l x P), root_command (l x C), df (l x 10K)]`` (:meth:`pipeline.terms.layout.ObservationLayout.flatten`),
and acts with a diagonal
Gaussian around the policy's joint targets:

    a ~ N(mu, sigma^2),   mu = denormalize(pi(o_(t-l+1..t)))   (absolute joint position targets, rad)

so at the start of post-training ``mu`` is the BC + DAgger policy's action exactly, and ``sigma`` (rsl_rl's
:class:`~rsl_rl.modules.distribution.GaussianDistribution`, learned, state-independent) is the only new parameter.
The VAE stays frozen (paper App. B: only the policy is fine-tuned).
"""

from __future__ import annotations

import torch
from rsl_rl.models import MLPModel
from rsl_rl.modules.distribution import GaussianDistribution
from tensordict import TensorDict
from torch import nn

from train.policy import InteractionPolicy, load_policy


class InteractionActor(MLPModel):
    """rsl_rl's model interface (``forward``, the distribution's properties, ``update_normalization``) around an
    :class:`~train.policy.InteractionPolicy` loaded from ``policy_path`` (module docstring). ``init_std`` is the
    exploration noise at the start, in radians of joint target."""

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        policy_path: str,
        init_std: float = 0.1,
    ) -> None:
        nn.Module.__init__(self)
        self.policy: InteractionPolicy = load_policy(policy_path)
        self.policy.train()
        layout = self.policy.layout
        self.obs_groups = list(obs_groups[obs_set])
        self.obs_dim = sum(int(obs[g].shape[-1]) for g in self.obs_groups)
        want = layout.observation.flat_dim
        if self.obs_dim != want or output_dim != layout.action_dim:
            raise ValueError(
                f"{policy_path}: the policy reads {want} and drives {layout.action_dim}, "
                f"the environment gives {self.obs_dim} and takes {output_dim}"
            )
        self.obs_normalization = False
        self.obs_normalizer = nn.Identity()
        self.distribution = GaussianDistribution(output_dim, init_std=init_std, std_type="log")

    def get_latent(self, obs: TensorDict, masks=None, hidden_state=None) -> torch.Tensor:
        return torch.cat([obs[g] for g in self.obs_groups], dim=-1)

    def forward(self, obs: TensorDict, masks=None, hidden_state=None, stochastic_output: bool = False) -> torch.Tensor:
        windows = self.policy.layout.observation.split(self.get_latent(obs))
        mean = self.policy.norm["action"].denormalize(self.policy(*windows))
        if stochastic_output:
            self.distribution.update(mean)
            return self.distribution.sample()
        return mean
