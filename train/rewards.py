"""The post-training reward (paper App. "Reward Design", table "Reward components"), one plain function per term
over batched arrays, written once for numpy (the CPU environment) and torch (a GPU backend) alike
(:mod:`pipeline.distance.array_ns`). Every term returns one value per environment, unweighted; :class:`RewardWeights`
holds the table's weights and :func:`total` sums ``weight * term``:

=================  ==========================================================  ======
term               formulation                                                 weight
=================  ==========================================================  ======
root tracking      ``-||x_root - c_root||^2``                                    1.0
interaction style  ``max(0, 1 - 0.25 (D(z) - 1)^2)`` (AIP, :func:`lsgan_reward`)  2.0
motion style       ``max(0, 1 - 0.25 (D(s) - 1)^2)`` (AMP)                       1.0
object tracking    ``exp(-||x_obj - x~_obj||^2 / sigma^2)``                      1.0
action rate        ``||a_t - a_(t-1)||^2``                                       -5.0
termination        1 on an early termination (a fall), not on a time-out        -10.0
joint limits       the number of joints outside their soft limits                -5.0
=================  ==========================================================  ======

The table lists the penalties' weights as magnitudes with the sign in the description ("penalizes", "penalty");
here the sign is in the weight, so every term is a plain measurement.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from pipeline.distance.array_ns import namespace


@dataclass(frozen=True)
class RewardWeights:
    """One weight per term (the paper's baseline values; "may be adjusted per task") and the object-tracking
    tolerance ``object_sigma_m``."""

    root_tracking: float = 1.0
    interaction_style: float = 2.0
    motion_style: float = 1.0
    object_tracking: float = 1.0
    action_rate: float = -5.0
    termination: float = -10.0
    joint_limits: float = -5.0
    object_sigma_m: float = 0.3

    def terms(self) -> dict[str, float]:
        """The weights by term name (``object_sigma_m`` is a tolerance, not a weight)."""
        return {k: v for k, v in asdict(self).items() if k != "object_sigma_m"}


def root_tracking(root_pos, command_pos):
    """(N,) ``-||x_root - c_root||^2``: the root position against the commanded root trajectory's, (N, 3) each."""
    return -((root_pos - command_pos) ** 2).sum(-1)


def object_tracking(object_pos, object_target, sigma: float):
    """(N,) ``exp(-||x_obj - x~_obj||^2 / sigma^2)``: the object against its desired trajectory, (N, 3) each."""
    xp = namespace(object_pos)
    return xp.exp(-((object_pos - object_target) ** 2).sum(-1) / sigma**2)


def action_rate(action, last_action):
    """(N,) ``||a_t - a_(t-1)||^2`` over the joint targets, (N, J) each."""
    return ((action - last_action) ** 2).sum(-1)


def termination(terminated, timed_out):
    """(N,) 1.0 where an episode ended early (a fall; ``terminated`` and not ``timed_out``), else 0.0."""
    return (terminated & ~timed_out) * 1.0


def joint_limits(q, lower, upper, soft: float = 0.9):
    """(N,) the number of joints outside their soft limits: the range ``[lower, upper]`` (J,) shrunk about its
    middle to ``soft`` of its width (mjlab's ``soft_joint_pos_limit_factor``), for joint angles ``q`` (N, J)."""
    mid, half = (upper + lower) / 2, soft * (upper - lower) / 2
    return ((q < mid - half) | (q > mid + half)).sum(-1) * 1.0


def lsgan_reward(d):
    """(N,) the style reward of an LSGAN discriminator's output ``d`` (N,): ``max(0, 1 - 0.25 (d - 1)^2)``, 1 where
    the discriminator is sure the sample is from the reference (d = 1), 0 from d <= -1 (sure it is the policy's)."""
    return (1.0 - 0.25 * (d - 1.0) ** 2).clip(0.0, None)


def total(terms: dict, weights: RewardWeights):
    """(N,) ``sum_k weight_k * term_k`` over the terms given (a term left out, e.g. the AIP's in the -AIP
    ablation, adds nothing); an unknown term name is an error."""
    w = weights.terms()
    unknown = sorted(set(terms) - set(w))
    if unknown:
        raise KeyError(f"unknown reward terms {unknown}; known: {sorted(w)}")
    return sum(w[k] * v for k, v in terms.items())
