"""The mjlab backend's terms, which :mod:`train.mjlab_env` assembles into the environment: :class:`Worlds`, the
episodes' reference tracks on the device and what each world runs; the restart event :func:`start_episodes`; the noisy
joint-target action; and the observation, reward and termination terms, plain functions ``(env, **params) ->
(N, ...)`` that call the CPU environment's own functions on torch tensors read from MuJoCo Warp's data."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from mjlab.envs import ManagerBasedRlEnv
from mjlab.envs.mdp.actions import JointPositionAction, JointPositionActionCfg
from mjlab.managers.event_manager import requires_model_fields

from features.compute import FeatureConfig
from physicalize.rollout import FALL_HEIGHT_DROP, FALL_TILT_COS
from pipeline.distance.field import boxes_query_links, cylinders_query_links
from pipeline.errors import InputError
from pipeline.robot import NQ_ROBOT, NUM_JOINTS, NV_ROBOT
from pipeline.scene import build_spec
from pipeline.terms.interaction import interaction_features
from pipeline.terms.link_motion import link_motion, link_velocity
from pipeline.terms.observations import command_frames, proprioception, root_command_to
from train import rewards as R
from train.episodes import Episode
from train.mjlab_object import MODEL_FIELDS, Shapes, is_box, is_chair, write_object
from train.randomize import (
    INITIAL_STATE,
    RandomizationConfig,
    actuation_noise,
    draw_batch,
    perception_noise,
    perturbed_initial_state,
    turn,
)


def check_episodes(episodes: list[Episode]) -> None:
    """One-line error for an episode this backend cannot run: anything but one box or one chair."""
    for e in episodes:
        if not runs_on_mjlab(e):
            objects = e.simulated.robot.objects
            g = objects[0].geometry if len(objects) == 1 else None
            what = f"{len(objects)} objects" if g is None else getattr(g, "kind", type(g).__name__)
            why = f"the mjlab backend runs one box or chair, not {what}"
            raise InputError(e.simulated.robot.source, "objects", why)


def runs_on_mjlab(e: Episode) -> bool:
    return is_box(e) or is_chair(e)


class Worlds:
    """The episodes' reference tracks on the device (padded with their last frame to the longest) and what each
    world runs: its episode, the object's parts (:class:`train.mjlab_object.Shapes`) and height shift at the drawn
    scale, the command offset.

    :meth:`start` writes episodes into worlds; :func:`start_episodes` draws them (:meth:`draw`)."""

    def __init__(self, episodes: list[Episode], envs: int, randomization: RandomizationConfig, seed: int,
                 device: str, horizon_s: float = FeatureConfig().root_horizon_s):  # fmt: skip
        check_episodes(episodes)
        self.episodes, self.randomization, self.device = episodes, randomization, torch.device(device)
        self.torch_rng = torch.Generator(device=self.device).manual_seed(seed)
        frames = [e.simulated.frames for e in episodes]
        longest = max(frames)

        def pad(a: np.ndarray) -> torch.Tensor:
            a = np.concatenate([a, np.repeat(a[-1:], longest - len(a), axis=0)])
            return torch.as_tensor(a, dtype=torch.float32 if a.dtype.kind == "f" else torch.long, device=device)

        def stack(f) -> torch.Tensor:
            return torch.stack([pad(np.asarray(f(e))) for e in episodes])

        self.frames = torch.as_tensor(frames, device=device)
        self.qpos = stack(lambda e: e.simulated.robot.qpos)
        self.qvel = stack(lambda e: e.simulated.qvel)
        self.object = stack(lambda e: e.simulated.robot.objects[0].pose)
        self.command = stack(lambda e: command_frames(e.simulated.frames, e.simulated.robot.fps, horizon_s))
        self.torso_up = stack(lambda e: _torso_up(e.simulated))
        self.episode = torch.zeros(envs, dtype=torch.long, device=device)
        self.shapes = Shapes(episodes, self.device, randomization.cylinder_prob)
        self.parts = self.shapes.at(torch.zeros(envs, dtype=torch.long, device=device),
                                    torch.ones(envs, 3, device=device), torch.zeros(envs, device=device))  # fmt: skip
        self.dz = torch.zeros(envs, device=device)
        self.command_offset = torch.zeros(envs, 3, device=device)
        self.joint_range = build_spec((), episodes[0].profile).compile().jnt_range[1 : 1 + NUM_JOINTS]
        self.joint_limits = torch.as_tensor(self.joint_range.T, dtype=torch.float32, device=device)  # (lower, upper)
        self._bodies: dict[tuple[str, ...], torch.Tensor] = {}

    def __deepcopy__(self, memo) -> Worlds:
        """Shared, never copied: mjlab's managers deep-copy their terms' configurations, and every term must read
        what the restart event writes (with a copy per manager, the observation and reward terms read episode 0 and
        the first size in every world, whatever the worlds ran)."""
        return self

    def index(self, env: ManagerBasedRlEnv) -> tuple[torch.Tensor, torch.Tensor]:
        """``(episode, frame)`` per world: the reference frame ``min(t, T - 1)`` at the world's step ``t``."""
        e = self.episode
        return e, torch.minimum(env.episode_length_buf, self.frames[e] - 1)

    def draw(self, n: int) -> tuple[torch.Tensor, dict]:
        """``n`` starts on the device: episode indices and :func:`train.randomize.draw_batch`'s draws."""
        episode = torch.randint(len(self.episodes), (n,), generator=self.torch_rng, device=self.device)
        return episode, draw_batch(self.randomization, n, self.torch_rng)

    def bodies(self, env: ManagerBasedRlEnv, links: tuple[str, ...]) -> torch.Tensor:
        """The global body ids of ``links`` (looked up once per name list)."""
        if links not in self._bodies:
            robot = env.scene["robot"]
            ids = robot.indexing.body_ids[robot.find_bodies(list(links), preserve_order=True)[0]]
            self._bodies[links] = torch.as_tensor(ids, device=self.device)
        return self._bodies[links]

    def start(self, env: ManagerBasedRlEnv, ids: torch.Tensor, episode: torch.Tensor, draws: dict) -> None:
        """Worlds ``ids`` start episodes ``episode`` (n,) under ``draws`` (:func:`train.randomize.draw_batch`, or
        :func:`train.randomize.stack` of :class:`~train.randomize.Variation` s): the first state as
        :class:`train.env._Slot` builds it, all worlds at once, and the object's model fields."""
        v = {k: torch.as_tensor(a, device=self.device).to(torch.float32) for k, a in draws.items()}
        e = torch.as_tensor(episode, device=self.device)
        dz = self.shapes.floor_shift(e, v["scale"])
        start = self.object[e, 0].clone()
        start[:, 2] += dz
        qpos = torch.cat([self.qpos[e, 0], start], 1)
        qpos = perturbed_initial_state(qpos, self.joint_range, [NQ_ROBOT], *(v[k] for k in INITIAL_STATE))
        self.episode[ids], self.dz[ids] = e, dz
        parts = self.shapes.at(e, v["scale"], v["cylinder"])
        for mine, new in zip(self.parts, parts):
            mine[ids] = new
        self.command_offset[ids] = v["command_offset"]
        d = env.sim.data
        d.qpos[ids] = qpos
        d.qvel[ids] = torch.cat([self.qvel[e, 0], torch.zeros(len(e), 6, device=self.device)], 1)
        write_object(env, ids, self.shapes, parts, v, e)


def _torso_up(sim) -> np.ndarray:
    """(T, 3) the reference torso's up-axis per frame (the fall test's reference)."""
    return link_motion(sim.robot.qpos, sim.qvel, ("torso_link",)).rot[:, 0, :, 2]


@requires_model_fields(*MODEL_FIELDS)
def start_episodes(env: ManagerBasedRlEnv, env_ids: torch.Tensor | None, worlds: Worlds) -> None:
    """Reset event: each world in ``env_ids`` starts a drawn episode (:meth:`Worlds.draw`)."""
    ids = torch.arange(env.num_envs, device=env.device) if env_ids is None else env_ids
    worlds.start(env, ids, *worlds.draw(len(ids)))


class NoisyJointTargets(JointPositionAction):
    """mjlab's joint-position action with the actuation noise (:func:`train.randomize.actuation_noise`)."""

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


# -- observation terms ---------------------------------------------------------------------------------------------


def _robot(env: ManagerBasedRlEnv) -> tuple[torch.Tensor, torch.Tensor]:
    return env.sim.data.qpos[:, :NQ_ROBOT], env.sim.data.qvel[:, :NV_ROBOT]


def applied_targets(env: ManagerBasedRlEnv) -> torch.Tensor:
    """(N, 29) the joint targets the last step applied (after the actuation noise); 0 before an episode's first."""
    a = env.action_manager.get_term("joints").raw_action  # scale 1, no offset: the targets, after the noise
    return torch.where(env.episode_length_buf[:, None] > 0, a, torch.zeros_like(a))


def proprio(env: ManagerBasedRlEnv) -> torch.Tensor:
    """(N, 93) :func:`pipeline.terms.observations.proprioception`."""
    return proprioception(*_robot(env), applied_targets(env))


def root_command(env: ManagerBasedRlEnv, worlds: Worlds) -> torch.Tensor:
    """(N, 12) the root command to the episode's root ``horizon`` ahead, turned by the world's command offset."""
    e, k = worlds.index(env)
    j = worlds.command[e, k]
    target = turn(worlds.qpos[e, j, :7], worlds.command_offset)
    return root_command_to(_robot(env)[0], target, worlds.qvel[e, j, :3])


def interaction(env: ManagerBasedRlEnv, worlds: Worlds, links: tuple[str, ...]) -> torch.Tensor:
    """(N, 10 K) u_t per DF link (:func:`pipeline.terms.interaction.interaction_features`) against the world's
    object, its box parts at their half-extents and centres (:func:`pipeline.distance.field.boxes_query_links`, as
    the CPU environment queries boxes and chairs) or its cylinder
    (:func:`pipeline.distance.field.cylinders_query_links`)."""
    d, ids = env.sim.data, worlds.bodies(env, links)
    pos = d.xpos[:, ids]
    vel = link_velocity(pos, d.cvel[:, ids], d.subtree_com[:, env.scene["robot"].indexing.root_body_id][:, None])
    pose, p = d.qpos[:, NQ_ROBOT : NQ_ROBOT + 7], worlds.parts
    phi, grad = boxes_query_links(pos, pose, *((p.half[:, 0],) if worlds.shapes.parts == 1 else (p.half, p.centre)))
    if worlds.shapes.cylinders:
        phi_c, grad_c = cylinders_query_links(pos, pose, p.radius, p.length)
        phi, grad = torch.where(p.cylinder[:, None], phi_c, phi), torch.where(p.cylinder[:, None, None], grad_c, grad)
    return interaction_features(phi, grad, vel).reshape(len(pos), -1)


def interaction_seen(env: ManagerBasedRlEnv, worlds: Worlds, links: tuple[str, ...]) -> torch.Tensor:
    """:func:`interaction` with the perception noise: what the policy reads."""
    return perception_noise(interaction(env, worlds, links), worlds.randomization.df_noise, worlds.torch_rng)


# -- reward and termination terms ------------------------------------------------------------------------------------


def root_tracking(env: ManagerBasedRlEnv, worlds: Worlds) -> torch.Tensor:
    e, k = worlds.index(env)
    return R.root_tracking(_robot(env)[0][:, :3], worlds.qpos[e, k, :3])


def object_tracking(env: ManagerBasedRlEnv, worlds: Worlds, sigma: float) -> torch.Tensor:
    e, k = worlds.index(env)
    target = worlds.object[e, k, :3].clone()
    target[:, 2] += worlds.dz  # the track raised as the first pose (Worlds.start)
    return R.object_tracking(env.sim.data.qpos[:, NQ_ROBOT : NQ_ROBOT + 3], target, sigma)


def action_rate(env: ManagerBasedRlEnv) -> torch.Tensor:
    """The policy's targets against the step before's; 0 on an episode's first step (as the CPU environment)."""
    a, last = env.action_manager.action, env.action_manager.prev_action
    return torch.where(env.episode_length_buf <= 1, 0.0, R.action_rate(a, last))


def termination(env: ManagerBasedRlEnv) -> torch.Tensor:
    m = env.termination_manager
    return R.termination(m.terminated, m.time_outs)


def joint_limits(env: ManagerBasedRlEnv, worlds: Worlds, soft: float) -> torch.Tensor:
    lower, upper = worlds.joint_limits
    return R.joint_limits(_robot(env)[0][:, 7:], lower, upper, soft)


def fell(env: ManagerBasedRlEnv, worlds: Worlds) -> torch.Tensor:
    """:func:`physicalize.rollout.fallen` per world: the pelvis too low or the torso tilted from the reference's."""
    e, k = worlds.index(env)
    up = env.sim.data.xmat[:, worlds.bodies(env, ("torso_link",))[0]].reshape(-1, 3, 3)[:, :, 2]
    low = _robot(env)[0][:, 2] < worlds.qpos[e, k, 2] - FALL_HEIGHT_DROP
    return low | ((up * worlds.torso_up[e, k]).sum(-1) < FALL_TILT_COS)


def reference_end(env: ManagerBasedRlEnv, worlds: Worlds) -> torch.Tensor:
    return env.episode_length_buf >= worlds.frames[worlds.episode] - 1
