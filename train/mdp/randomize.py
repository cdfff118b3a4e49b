"""The six domain randomisations of post-training (paper App. "Domain Randomization"), as plain functions over one
episode's draw (:class:`Variation`) or a batch of arrays. The paper names the dimensions, not the ranges; the ranges
in :class:`RandomizationConfig` are ours, each small against what the BC + DAgger policy already tolerates, and a
range of 0 (or a factor range of (1, 1)) switches one off:

1. **object geometry**: a per-axis scale (the ``scale`` of the episode draw, 0.4-1.6 as the evaluation's), a box
   drawn as a circular cylinder of the same height and mean half-width with ``cylinder_prob`` (primitive boxes
   only);
2. **physical properties**: the object's mass and frictions (with the robot and with the floor) times a factor, a
   restitution coefficient
   (:func:`object_physics`; the scene builder turns restitution into a contact spring);
3. **initial conditions**: the robot's root and the objects shifted in x, y and turned about z, the joints moved
   around the episode's first (standing) pose (:func:`perturb_initial_state`); the placement perturbation of the
   paper's "object geometry" is this one's object offset;
4. **command perturbation**: the episode's root command target shifted and turned by a per-episode offset
   (:func:`perturb_command`);
5. **actuation noise**: zero-mean Gaussian noise on the joint targets before they are applied
   (:func:`actuation_noise`);
6. **perception noise**: zero-mean Gaussian noise on the DF features the policy reads (phi, its gradient, the two
   velocities), not on what the AIP discriminator reads (:func:`perception_noise`).

(1), (2), (3) and (4) are drawn once per episode (:func:`draw`); (5) and (6) every step.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from pipeline.clip import ObjectTrack
from pipeline.geometry import ObjectPhysics, Primitive
from pipeline.robot import NQ_ROBOT, NUM_JOINTS
from pipeline.xp import as_float, concat, namespace


@dataclass(frozen=True)
class RandomizationConfig:
    """The ranges (module docstring). Offsets are uniform in ``+-range``; factors uniform in ``(lo, hi)``."""

    scale: tuple[float, float] = (0.4, 1.6)
    cylinder_prob: float = 0.5
    mass_factor: tuple[float, float] = (0.5, 1.5)
    friction_factor: tuple[float, float] = (0.6, 1.25)
    restitution: tuple[float, float] = (0.0, 0.3)
    robot_xy_m: float = 0.03
    robot_yaw_rad: float = 0.05
    joint_noise_rad: float = 0.03
    object_xy_m: float = 0.03
    object_yaw_rad: float = 0.1
    command_xy_m: float = 0.05
    command_yaw_rad: float = 0.05
    action_noise_rad: float = 0.02
    df_noise: tuple[float, float, float] = (0.005, 0.02, 0.02)  # phi [m], grad [1], velocities [m/s]

    @classmethod
    def off(cls) -> RandomizationConfig:
        """No randomisation at all (the ``-Rand`` ablation): scale 1.0, nothing perturbed."""
        ranges = {"scale": (1.0, 1.0), "mass_factor": (1.0, 1.0), "friction_factor": (1.0, 1.0)}
        ranges |= {"restitution": (0.0, 0.0), "df_noise": (0.0, 0.0, 0.0)}
        return cls(**{f.name: ranges.get(f.name, 0.0) for f in fields(cls)})


@dataclass(frozen=True)
class Variation:
    """One episode's draw: ``scale`` (3,), ``cylinder``, the physical factors and restitution, the ``(dx, dy, dyaw)``
    offsets of the robot, the objects and the command, and the ``joint_noise`` (29,)."""

    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    cylinder: bool = False
    mass_factor: float = 1.0
    friction_factor: float = 1.0
    restitution: float = 0.0
    robot_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    object_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    command_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    joint_noise: tuple[float, ...] = (0.0,) * NUM_JOINTS


def draw(cfg: RandomizationConfig, rng: np.random.Generator) -> Variation:
    """One episode's :class:`Variation` under ``cfg`` (the first row of :func:`draw_batch`)."""
    b = draw_batch(cfg, 1, rng)
    row = {k: v[0].tolist() for k, v in b.items()}
    return Variation(**{k: tuple(v) if isinstance(v, list) else v for k, v in row.items()})


def draw_batch(cfg: RandomizationConfig, n: int, rng) -> dict:
    """``n`` episodes' draws at once: :class:`Variation`'s fields as arrays with a leading ``(n,)`` axis, numpy with
    a numpy ``rng``, torch with a ``torch.Generator`` (on its device: the mjlab backend draws its restarts there)."""

    def uniform(lo: float, hi: float, *shape: int):
        if isinstance(rng, np.random.Generator):
            return rng.uniform(lo, hi, (n, *shape))
        import torch

        return lo + (hi - lo) * torch.rand((n, *shape), generator=rng, device=rng.device, dtype=torch.float64)

    def offset(xy: float, yaw: float):
        a = uniform(-1.0, 1.0, 3)
        return a * as_float([xy, xy, yaw], namespace(a), like=a)

    return {
        "scale": uniform(*cfg.scale, 3),
        "cylinder": uniform(0.0, 1.0) < cfg.cylinder_prob,
        "mass_factor": uniform(*cfg.mass_factor),
        "friction_factor": uniform(*cfg.friction_factor),
        "restitution": uniform(*cfg.restitution),
        "robot_offset": offset(cfg.robot_xy_m, cfg.robot_yaw_rad),
        "object_offset": offset(cfg.object_xy_m, cfg.object_yaw_rad),
        "command_offset": offset(cfg.command_xy_m, cfg.command_yaw_rad),
        "joint_noise": uniform(-1.0, 1.0, NUM_JOINTS) * cfg.joint_noise_rad,
    }


def stack(variations: list[Variation]) -> dict[str, np.ndarray]:
    """Episodes' :class:`Variation` s as :func:`draw_batch`'s arrays."""
    return {f.name: np.array([getattr(v, f.name) for v in variations]) for f in fields(Variation)}


def vary_shape(o: ObjectTrack, v: Variation) -> ObjectTrack:
    """A primitive box drawn as a circular cylinder along z when ``v.cylinder``
    (:meth:`pipeline.geometry.Primitive.as_cylinder`); any other object as it is."""
    g = o.geometry
    if not (v.cylinder and isinstance(g, Primitive) and g.kind == "box"):
        return o
    return replace(o, geometry=g.as_cylinder())


def object_physics(o: ObjectTrack, v: Variation) -> ObjectPhysics:
    """The object's own mass and both frictions (with the robot, with the floor) times the draw's factors, with the
    draw's restitution."""
    p = o.physics()
    f = v.friction_factor
    return ObjectPhysics(p.mass * v.mass_factor, p.friction * f, p.floor_friction * f, v.restitution)


def placed(o: ObjectTrack, v: Variation) -> tuple[float, ...]:
    """The object's first pose shifted and turned by ``v.object_offset`` (where a fixed object is built)."""
    pose = np.array(o.pose[0], dtype=float)
    _turn(pose, v.object_offset)
    return tuple(pose)


def turn(pose, offset):
    """(N, 7) free-body poses ``(x y z qw qx qy qz)`` (N, 7) shifted by ``(dx, dy)`` and turned by ``dyaw`` about z,
    ``offset`` (N, 3): ``q' = (cos dyaw/2, 0, 0, sin dyaw/2) q``; numpy or torch alike (the CPU environment turns one
    pose at a time, :mod:`train.envs.mjlab.env` a batch)."""
    xp = namespace(pose)
    c, s = xp.cos(offset[:, 2] / 2), xp.sin(offset[:, 2] / 2)
    w, x, y, z = pose[:, 3], pose[:, 4], pose[:, 5], pose[:, 6]
    quat = [c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w]
    return xp.stack([pose[:, 0] + offset[:, 0], pose[:, 1] + offset[:, 1], pose[:, 2], *quat], 1)


def _turn(qpos7: np.ndarray, offset: tuple[float, float, float]) -> None:
    """:func:`turn` in place on one pose."""
    qpos7[:] = turn(qpos7[None, :7], np.asarray(offset, dtype=float)[None])[0]


def perturb_initial_state(qpos: np.ndarray, joint_range: np.ndarray, object_adr: list[int], v: Variation) -> None:
    """In place on one scene's ``qpos``: :func:`perturbed_initial_state` of ``v``."""
    b = stack([v])
    qpos[:] = perturbed_initial_state(qpos[None], joint_range, object_adr, *(b[k] for k in INITIAL_STATE))[0]


INITIAL_STATE = ("robot_offset", "object_offset", "joint_noise")
"""The draws :func:`perturbed_initial_state` reads, in its argument order."""


def perturbed_initial_state(qpos, joint_range, object_adr: list[int], robot_offset, object_offset, joint_noise):
    """(N, nq) scenes' first ``qpos`` with the robot's root and each free object (at ``object_adr``) shifted and
    turned about their own origin (:func:`turn` by ``robot_offset`` / ``object_offset``, (N, 3)) and the joints moved
    by ``joint_noise`` (N, 29), kept inside ``joint_range`` (29, 2); numpy or torch alike."""
    xp = namespace(qpos)
    out = qpos * 1.0
    out[:, :7] = turn(qpos[:, :7], robot_offset)
    lo, hi = (as_float(joint_range[:, k], xp, like=qpos) for k in (0, 1))
    q = qpos[:, 7:NQ_ROBOT] + joint_noise
    out[:, 7:NQ_ROBOT] = xp.minimum(xp.maximum(q, lo), hi)
    for adr in object_adr:
        out[:, adr : adr + 7] = turn(qpos[:, adr : adr + 7], object_offset)
    return out


def perturb_command(target_qpos: np.ndarray, v: Variation) -> np.ndarray:
    """The root command's target ``(x y z qw qx qy qz)`` shifted and turned by ``v.command_offset``."""
    out = np.array(target_qpos[:7], dtype=float)
    _turn(out, v.command_offset)
    return out


def actuation_noise(actions, sigma: float, rng):
    """``a + N(0, sigma^2)`` per joint target; numpy with a numpy ``rng``, torch with a ``torch.Generator``."""
    return actions + sigma * _standard_normal(actions, rng) if sigma > 0 else actions


def perception_noise(df, sigma: tuple[float, float, float], rng):
    """``u + N(0, s^2)`` on the DF features ``(N, K x 10)``, ``s`` per part of ``u = [phi, grad, v_norm, v_tan]``:
    ``sigma[0]`` on phi, ``sigma[1]`` on the gradient, ``sigma[2]`` on both velocities (numpy or torch, as
    :func:`actuation_noise`)."""
    if not any(sigma):
        return df
    xp = namespace(df)
    s = as_float([sigma[0]] + [sigma[1]] * 3 + [sigma[2]] * 6, xp, like=df)
    return df + _standard_normal(df, rng) * concat([s] * (df.shape[-1] // 10), xp)


def _standard_normal(like, rng):
    """Standard normal samples shaped as ``like``, from ``rng`` (numpy ``Generator`` or ``torch.Generator``)."""
    if isinstance(rng, np.random.Generator):
        return rng.standard_normal(like.shape)
    import torch

    return torch.randn(like.shape, generator=rng, dtype=like.dtype, device=like.device)
