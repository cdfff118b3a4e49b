"""The LSGAN style discriminator (AIP / AMP): its loss falls, it tells reference from policy samples, and its
reward follows."""

import pytest
import torch

from train.discriminator import Discriminator, DiscriminatorConfig

torch.set_num_threads(1)


def _fit(config: DiscriminatorConfig, steps: int = 300):
    g = torch.Generator().manual_seed(0)
    reference = torch.randn(512, 8, generator=g) + 1.0  # "valid interaction" latents
    policy = torch.randn(512, 8, generator=g) - 1.0  # the policy's, elsewhere
    torch.manual_seed(0)
    d = Discriminator(reference, config)
    opt = torch.optim.Adam(d.parameters(), lr=1e-3)
    first = None
    for _ in range(steps):
        loss, parts = d.loss(reference, policy)
        opt.zero_grad()
        loss.backward()
        opt.step()
        first = first if first is not None else parts
    return d, reference, policy, first, parts


def test_the_discriminator_learns_the_reference_and_rewards_it():
    d, reference, policy, first, last = _fit(DiscriminatorConfig(hidden=(64, 64)))
    assert last["lsgan"] < 0.5 * first["lsgan"] and last["grad_penalty"] > 0
    assert last["d_ref"] > 0.5 and last["d_pol"] < -0.5
    r_ref, r_pol = d.reward(reference), d.reward(policy)
    assert r_ref.mean() > 0.8 and r_pol.mean() < 0.2
    assert 0.0 <= float(r_pol.min()) and float(r_ref.max()) <= 1.0


def test_the_gradient_penalty_keeps_the_boundary_soft():
    """Without the penalty the scores saturate further apart: its weight is what bounds the slope at the reference."""
    soft, *_, parts_soft = _fit(DiscriminatorConfig(hidden=(64, 64), gp_weight=5.0))
    hard, *_, parts_hard = _fit(DiscriminatorConfig(hidden=(64, 64), gp_weight=0.0))
    assert parts_hard["grad_penalty"] == 0.0
    assert parts_soft["d_ref"] - parts_soft["d_pol"] < parts_hard["d_ref"] - parts_hard["d_pol"]


def test_bad_shapes_are_refused():
    d = Discriminator(torch.randn(4, 3), DiscriminatorConfig(hidden=(8,)))
    with pytest.raises(ValueError, match="reads 3-d samples, got 5"):
        d(torch.randn(2, 5))
    with pytest.raises(ValueError, match="reference buffer must be"):
        Discriminator(torch.randn(1, 3))
