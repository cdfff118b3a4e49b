"""The post-training reward (paper App. "Reward Design", table "Reward components"), one plain function per term
over batched arrays, written once for numpy (the CPU environment) and torch (a GPU backend) alike
(:mod:`pipeline.xp`). Every term returns one value per environment, unweighted; :class:`RewardWeights`
holds the table's weights and :func:`total` sums ``weight * term``:

=================  ==========================================================  ===============
term               formulation                                                 weight
=================  ==========================================================  ===============
root tracking      ``-||x_root - c_root||^2``                                    1.0
interaction style  ``max(0, 1 - 0.25 (D(z) - 1)^2)`` (AIP, :func:`lsgan_reward`)  2.0
motion style       ``max(0, 1 - 0.25 (D(s) - 1)^2)`` (AMP)                       1.0
object tracking    ``exp(-||x_obj - x~_obj||^2 / sigma^2)``                      1.0
action rate        ``||a_t - a_(t-1)||^2``                                       -0.5 (table: 5)
termination        1 on an early termination (a fall), not on a time-out        -10.0
joint limits       the number of joints outside their soft limits                -5.0
=================  ==========================================================  ===============

The table lists the penalties' weights as magnitudes with the sign in the description ("penalizes", "penalty");
here the sign is in the weight, so every term is a plain measurement.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from pipeline.xp import namespace


@dataclass(frozen=True)
class RewardWeights:
    """One weight per term (the paper's baseline values; "may be adjusted per task"), the object-tracking
    tolerance ``object_sigma_m`` and the joint limits' ``soft_limit`` (fraction of each joint's range).

    The paper does not give its soft limits. They are the joints' own ranges here (1.0), not mjlab's 0.9: the
    valid episodes of the 100-clip synthetic corpus exceed 0.9 of the range on 0.56 / 0.91 / 0.09 / 0.70 joints per
    frame (PickUp / SitStand / Push / Carry; elbows, ankle rolls, waist pitch, knees), so at 0.9 the term charges the
    demonstrated motion 2.8-4.6 per step, more than every positive term together; at 1.0: 0.07 / 0.01 / 0 / 0.04.

    The action rate's weight is 0.5, not the table's 5: with joint targets in radians the BC + DAgger policy changes
    them by ||a_t - a_(t-1)||^2 = 1.3-2.0 per step under the exploration noise (sigma 0.1 rad alone adds
    2 x 29 x 0.01 = 0.58; the teacher's own targets: 0.33-0.59 per frame on the corpus), so at 5 every living step
    costs 6-10, more than the positive terms can give (at most 4), and a fall (-10 once) ends the charges: in a
    600-iteration run at 5 the falls per iteration rose from 2.8 to 3.6 while the task reward "improved". At 0.5 a
    step of the pre-trained policy nets about +1, so a fall costs the termination and every step it cuts short."""

    root_tracking: float = 1.0
    interaction_style: float = 2.0
    motion_style: float = 1.0
    object_tracking: float = 1.0
    action_rate: float = -0.5
    termination: float = -10.0
    joint_limits: float = -5.0
    object_sigma_m: float = 0.3
    soft_limit: float = 1.0

    def terms(self) -> dict[str, float]:
        """The weights by term name (``object_sigma_m`` and ``soft_limit`` are tolerances, not weights)."""
        return {k: v for k, v in asdict(self).items() if k not in ("object_sigma_m", "soft_limit")}


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
