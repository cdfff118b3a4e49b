"""The mjlab backend's reference state (mjlab's command-term idea): :class:`Worlds` holds the episodes' reference
tracks on the device and what each world runs; every observation, reward, termination and event term reads it."""

from __future__ import annotations

import numpy as np
import torch
from mjlab.envs import ManagerBasedRlEnv

from pipeline.errors import InputError
from pipeline.robot import NQ_ROBOT, NUM_JOINTS, NV_ROBOT
from pipeline.scene import build_spec
from pipeline.terms.layout import ROOT_HORIZON_S
from pipeline.terms.link_motion import link_motion
from pipeline.terms.observations import command_frames
from train.envs.mjlab.object import Shapes, is_box, is_chair, write_object
from train.episodes import Episode
from train.mdp.randomize import INITIAL_STATE, RandomizationConfig, draw_batch, perturbed_initial_state


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
    world runs: its episode, the object's parts (:class:`train.envs.mjlab.object.Shapes`) and height shift at the drawn
    scale, the command offset.

    :meth:`start` writes episodes into worlds; :func:`start_episodes` draws them (:meth:`draw`)."""

    def __init__(self, episodes: list[Episode], envs: int, randomization: RandomizationConfig, seed: int,
                 device: str, horizon_s: float = ROOT_HORIZON_S):  # fmt: skip
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
        """``n`` starts on the device: episode indices and :func:`train.mdp.randomize.draw_batch`'s draws."""
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
        """Worlds ``ids`` start episodes ``episode`` (n,) under ``draws`` (:func:`train.mdp.randomize.draw_batch`, or
        :func:`train.mdp.randomize.stack` of :class:`~train.mdp.randomize.Variation` s): the first state as
        :class:`train.envs.cpu.env.EnvSlot` builds it, all worlds at once, and the object's model fields."""
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


def robot_state(env: ManagerBasedRlEnv) -> tuple[torch.Tensor, torch.Tensor]:
    return env.sim.data.qpos[:, :NQ_ROBOT], env.sim.data.qvel[:, :NV_ROBOT]
