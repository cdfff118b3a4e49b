"""Post-training on mjlab (MuJoCo Warp, ``--backend mjlab``): the environment of :mod:`train.envs.cpu.vec_env` as an
mjlab
``ManagerBasedRlEnv`` over ``N`` worlds, so a GPU steps thousands of episodes at once. Nothing is written twice:

* **scene**: the robot of :func:`pipeline.scene.build_spec` (the episodes' actuator profile, the floor, the solver
  options) and the object of :func:`train.envs.mjlab.object.entity_spec`, as two mjlab entities; the joint targets go
  through mjlab's joint-position action (absolute targets, scale 1) with the actuation noise added;
* **observations, rewards, terminations**: plain term functions calling the CPU environment's own functions on
  torch tensors read from the warp data (:mod:`pipeline.terms.observations`, :mod:`pipeline.terms.interaction`,
  :func:`pipeline.terms.link_motion.link_velocity`, the box field of :mod:`pipeline.distance.primitive`,
  :mod:`train.mdp.rewards`, the fall test of :mod:`pipeline.terms.fall`), by kind in :mod:`train.envs.mjlab`'s
  ``observations``, ``rewards``, ``terminations``, ``events`` and ``actions``; ``policy`` is the ``l``-step windows
  in :class:`pipeline.terms.layout.ObservationLayout`'s flat order (mjlab's per-term history, the terms in the
  layout's order), ``critic`` the current step;
* **episodes**: a restart draws the episode and its randomisations on the device with the CPU environment's own
  functions (:func:`train.mdp.randomize.draw_batch`, :func:`train.mdp.randomize.perturbed_initial_state`, written once
  for
  numpy and torch), for all restarting worlds at once, and writes the first state and the object's size, mass,
  inertia and friction into them (per-world model fields); the command offset (:func:`train.mdp.randomize.turn`) and
  the perception noise apply every step.

Its speed on a GPU (``make bench-train-mjlab``) is in ``BENCHMARKS.md``: the restarts are drawn and started on the
device for all worlds at once, and the object's derived constants written directly rather than through MuJoCo Warp's
``set_const`` (:func:`train.envs.mjlab.object.rigid_body`), because each was measured faster there.

:class:`MjlabPostTrainEnv` is rsl_rl's ``VecEnv`` over it with :class:`train.envs.cpu.vec_env.PostTrainEnv`'s
observations
and extras, so :mod:`train.aip` trains either. It runs the episodes of one box or one chair, the four tasks of the
default corpus, with the six randomisations (:mod:`train.envs.mjlab.object`: every world's object has the most box parts
any episode needs and a cylinder slot for the boxes drawn as cylinders). Not on this backend yet (a one-line error,
or left out and said so): mesh objects (mjlab fixes a world's meshes at start-up: they need its pre-built variants).
Two known differences from native MuJoCo: MuJoCo Warp makes at most one contact between a capsule (the G1's limbs)
and the cylinder, and warns so at start-up; the fall test reads the torso's orientation one physics step stale
(mjlab computes terminations before its single ``forward``).
"""

from __future__ import annotations

import sys

import mujoco
import torch
from mjlab.actuator.xml_actuator import XmlActuatorCfg
from mjlab.entity import EntityArticulationInfoCfg, EntityCfg
from mjlab.envs import ManagerBasedRlEnv, ManagerBasedRlEnvCfg
from mjlab.managers import (
    EventTermCfg,
    ObservationGroupCfg,
    ObservationTermCfg,
    RewardTermCfg,
    TerminationTermCfg,
)
from mjlab.scene import SceneCfg
from mjlab.sim import MujocoCfg, SimulationCfg
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from pipeline.errors import InputError
from pipeline.robot import NUM_JOINTS
from pipeline.scene import IMPRATIO, SceneObject, build_spec
from pipeline.terms.layout import AMP_STATE, DF_LINKS, PHYSICS_TIMESTEP, SUBSTEPS, ObservationLayout
from train.envs.config import PostEnvConfig
from train.envs.mjlab.actions import NoisyJointTargetsCfg
from train.envs.mjlab.events import start_episodes
from train.envs.mjlab.object import add_object_floor_pairs, entity_spec
from train.envs.mjlab.observations import interaction, interaction_seen, proprio, root_command
from train.envs.mjlab.rewards import action_rate, joint_limits, object_tracking, root_tracking, termination
from train.envs.mjlab.terminations import fell, reference_end
from train.envs.mjlab.worlds import Worlds, check_episodes, runs_on_mjlab
from train.episodes import Episode
from train.mdp import rewards as R

CONTACTS, CONSTRAINT_ROWS = 64, 512
"""Per world: MuJoCo Warp allocates contacts and constraint rows up front (past the limit contacts are dropped). The
G1 standing with a box in its hands needed up to 96 rows with elliptic cones in a first 2-world run; the QP teacher
in the native scene, at the end of each control step, measured up to 35 contacts and 105 rows with a box, 46 and 136
sitting on a chair (4 episodes per task at scales 0.4, 1.0 and 1.6)."""


def runnable_episodes(episodes: list[Episode]) -> list[Episode]:
    """The episodes this backend runs (one box or chair); says on stderr how many it leaves to the CPU backend, and
    is a one-line error when none is left."""
    keep = [e for e in episodes if runs_on_mjlab(e)]
    if not keep:
        check_episodes(episodes)
    if len(keep) < len(episodes):
        left = sorted({e.task for e in episodes if not runs_on_mjlab(e)})
        print(f"mjlab backend: {len(keep)} of {len(episodes)} episodes; {', '.join(left)} (not one box or chair) run "
              "on the CPU backend only", file=sys.stderr)  # fmt: skip
    return keep


def check_device(device: str) -> None:
    """One-line error for a device mjlab cannot use: CUDA asked for and none visible."""
    if device.startswith("cuda") and not torch.cuda.is_available():
        why = "the mjlab backend needs a CUDA GPU and torch sees none; --device cpu runs it slowly (a smoke test)"
        raise InputError(None, "device", why)


# -- the environment -----------------------------------------------------------------------------------------------


def env_cfg(worlds: Worlds, envs: int, history: int, weights: R.RewardWeights,
            links: tuple[str, ...] = DF_LINKS, sensors: tuple = ()) -> ManagerBasedRlEnvCfg:  # fmt: skip
    """The mjlab configuration of ``envs`` worlds over ``worlds``' episodes (module docstring); ``sensors``: the
    scene's extra sensors (e.g. the vision student's depth camera, :func:`train.envs.mjlab.camera.depth_sensor_cfg`)."""
    profile = worlds.episodes[0].profile
    if any(e.profile != profile for e in worlds.episodes):
        raise InputError(worlds.episodes[0].simulated.robot.source, "actuator_profile", "episodes of two profiles")
    shapes = worlds.shapes  # the object entity has the most parts any episode needs (train.envs.mjlab.object)
    first = worlds.episodes[int(shapes.chair.int().argmax()) if shapes.parts > 1 else 0].simulated.robot.objects[0]
    robot = EntityCfg(
        spec_fn=lambda: _robot_spec(profile),
        articulation=EntityArticulationInfoCfg(actuators=(XmlActuatorCfg(target_names_expr=(".*_joint",)),)),
    )
    scene_object = SceneObject("object", first.geometry, first.physics())
    obj = EntityCfg(spec_fn=lambda: entity_spec(shapes, scene_object))
    w, lw = {"worlds": worlds}, {"worlds": worlds, "links": links}

    def obs(func, params=None, steps=0) -> ObservationTermCfg:
        return ObservationTermCfg(func=func, params=params or {}, history_length=steps)

    def reward(func, weight: float, **params) -> RewardTermCfg:
        return RewardTermCfg(func=func, weight=weight, params=params)

    # the terms in the layout's order: mjlab concatenates a group's terms (each its l-step history) in this order
    seen = {"proprio": (proprio, None), "root_command": (root_command, w), "df": (interaction_seen, lw)}
    true = {**seen, "df": (interaction, lw)}
    terms = ObservationLayout(links, history).step_slices()
    policy = {k: obs(*seen[k], history) for k in terms}
    critic = {k: obs(*true[k]) for k in terms}
    frames = int(worlds.frames.max())
    return ManagerBasedRlEnvCfg(
        decimation=SUBSTEPS,
        scene=SceneCfg(
            num_envs=envs,
            entities={"robot": robot, "object": obj},
            spec_fn=lambda spec: add_object_floor_pairs(spec, scene_object),
            sensors=tuple(sensors),
        ),
        sim=SimulationCfg(nconmax=CONTACTS, njmax=CONSTRAINT_ROWS, mujoco=MujocoCfg(**_options())),
        observations={"policy": ObservationGroupCfg(terms=policy), "critic": ObservationGroupCfg(terms=critic)},
        actions={
            "joints": NoisyJointTargetsCfg(
                entity_name="robot", actuator_names=(".*",), worlds=worlds, sigma=worlds.randomization.action_noise_rad
            )
        },  # fmt: skip
        rewards={
            "root_tracking": reward(root_tracking, weights.root_tracking, worlds=worlds),
            "object_tracking": reward(
                object_tracking, weights.object_tracking, worlds=worlds, sigma=weights.object_sigma_m
            ),  # fmt: skip
            "action_rate": reward(action_rate, weights.action_rate),
            "termination": reward(termination, weights.termination),
            "joint_limits": reward(joint_limits, weights.joint_limits, worlds=worlds, soft=weights.soft_limit),
        },
        terminations={
            "fell": TerminationTermCfg(func=fell, params=w),
            "reference_end": TerminationTermCfg(func=reference_end, params=w, time_out=True),
        },
        events={"start_episodes": EventTermCfg(func=start_episodes, mode="reset", params=w)},
        episode_length_s=(frames + 1) * PHYSICS_TIMESTEP * SUBSTEPS,
        auto_reset=False,  # restarts after the style samples are taken (MjlabPostTrainEnv.step)
        scale_rewards_by_dt=False,  # the paper's weights are per step
    )


def _options() -> dict:
    """:func:`pipeline.scene.build_spec`'s solver options as mjlab's ``MujocoCfg`` (the scene's options are mjlab's
    to set: an attached spec's are dropped)."""
    return {"timestep": PHYSICS_TIMESTEP, "integrator": "implicitfast", "cone": "elliptic", "impratio": IMPRATIO}


def _robot_spec(profile) -> mujoco.MjSpec:
    """:func:`pipeline.scene.build_spec`'s robot (actuators, floor) with MuJoCo's default options (:func:`_options`
    sets them; left in, mjlab warns that it drops them)."""
    spec, default = build_spec((), profile), mujoco.MjSpec().option
    for name in ("timestep", "integrator", "cone", "impratio"):
        setattr(spec.option, name, getattr(default, name))
    return spec


class MjlabPostTrainEnv(VecEnv):
    """rsl_rl's ``VecEnv`` over the mjlab environment, with :class:`train.envs.cpu.vec_env.PostTrainEnv`'s observations
    (``policy`` windows, ``critic`` current step) and extras (``style``, ``time_outs``, ``log``)."""

    def __init__(self, episodes: list[Episode], history: int, config: PostEnvConfig = PostEnvConfig(),
                 device: str = "cuda", sensors: tuple = ()):  # fmt: skip
        check_device(device)
        self.worlds = Worlds(episodes, config.envs, config.randomization, config.seed, device)
        cfg = env_cfg(self.worlds, config.envs, history, config.weights, sensors=sensors)
        self.env = ManagerBasedRlEnv(cfg, device=device)
        self.obs, _ = self.env.reset()
        self.cfg, self.device = config, torch.device(device)
        self.num_envs, self.num_actions = config.envs, NUM_JOINTS
        self.max_episode_length = int(self.worlds.frames.max())
        self.weights = {k: v for k, v in config.weights.terms().items() if k in self.env.reward_manager.active_terms}
        where = ObservationLayout(history=history).step_slices()  # the critic row's terms
        self.proprio, self.df = where["proprio"], where["df"]

    @property
    def episode_length_buf(self) -> torch.Tensor:
        return self.env.episode_length_buf

    def get_observations(self) -> TensorDict:
        return TensorDict({k: self.obs[k] for k in ("policy", "critic")}, batch_size=[self.num_envs])

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        before = self.obs["critic"][:, self.proprio][:, AMP_STATE]
        obs, reward, terminated, time_outs, _ = self.env.step(actions)
        critic = obs["critic"]
        style = {"df": critic[:, self.df], "transition": torch.cat([before, critic[:, self.proprio][:, AMP_STATE]], 1)}
        done = terminated | time_outs
        means = self._term_values().mean(0).tolist()  # one device sync for all terms
        log = {f"/reward/{k}": v / w for (k, w), v in zip(self.weights.items(), means)}
        if done.any():
            obs, _ = self.env.reset(env_ids=done.nonzero().squeeze(1))
        self.obs = obs
        extras = {"time_outs": time_outs & ~terminated, "style": style, "log": log}
        return self.get_observations(), reward, done, extras

    def _term_values(self) -> torch.Tensor:
        """(N, terms) each reward term's weighted value this step (mjlab keeps them in ``_step_reward``)."""
        return self.env.reward_manager._step_reward

    def close(self) -> None:
        self.env.close()
