"""The mjlab backend's observation terms: plain functions ``(env, **params) -> (N, dim)`` calling the CPU
environment's own functions (:mod:`pipeline.terms`) on torch tensors read from MuJoCo Warp's data."""

from __future__ import annotations

import torch
from mjlab.envs import ManagerBasedRlEnv

from pipeline.distance.field import boxes_query_links, cylinders_query_links
from pipeline.robot import NQ_ROBOT
from pipeline.terms.interaction import interaction_features
from pipeline.terms.link_motion import link_velocity
from pipeline.terms.observations import proprioception, root_command_to
from train.envs.mjlab.worlds import Worlds, robot_state
from train.mdp.randomize import perception_noise, turn


def applied_targets(env: ManagerBasedRlEnv) -> torch.Tensor:
    """(N, 29) the joint targets the last step applied (after the actuation noise); 0 before an episode's first."""
    a = env.action_manager.get_term("joints").raw_action  # scale 1, no offset: the targets, after the noise
    return torch.where(env.episode_length_buf[:, None] > 0, a, torch.zeros_like(a))


def proprio(env: ManagerBasedRlEnv) -> torch.Tensor:
    """(N, 93) :func:`pipeline.terms.observations.proprioception`."""
    return proprioception(*robot_state(env), applied_targets(env))


def root_command(env: ManagerBasedRlEnv, worlds: Worlds) -> torch.Tensor:
    """(N, 12) the root command to the episode's root ``horizon`` ahead, turned by the world's command offset."""
    e, k = worlds.index(env)
    j = worlds.command[e, k]
    target = turn(worlds.qpos[e, j, :7], worlds.command_offset)
    return root_command_to(robot_state(env)[0], target, worlds.qvel[e, j, :3])


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
