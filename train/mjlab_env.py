"""Post-training on mjlab (MuJoCo Warp, ``--backend mjlab``): the environment of :mod:`train.post_env` as an mjlab
``ManagerBasedRlEnv`` over ``N`` worlds, so a GPU steps thousands of episodes at once. Nothing is written twice:

* **scene**: the robot of :func:`pipeline.scene.build_spec` (the episodes' actuator profile, the floor, the solver
  options) and the object of :func:`train.mjlab_object.entity_spec`, as two mjlab entities; the joint targets go
  through mjlab's joint-position action (absolute targets, scale 1) with the actuation noise added;
* **observations, rewards, terminations**: plain term functions calling the CPU environment's own functions on
  torch tensors read from the warp data (:mod:`pipeline.terms.observations`, :mod:`pipeline.terms.interaction`,
  :func:`pipeline.terms.link_motion.link_velocity`, the box field of :mod:`pipeline.distance.primitive`,
  :mod:`train.rewards`, the fall test of :mod:`physicalize.rollout`); ``policy`` is the ``l``-step windows in
  :func:`train.rl_model.flatten_windows`'s layout (mjlab's per-term history), ``critic`` the current step;
* **episodes**: a restart draws the episode and its randomisations on the device with the CPU environment's own
  functions (:func:`train.randomize.draw_batch`, :func:`train.randomize.perturbed_initial_state`, written once for
  numpy and torch), for all restarting worlds at once, and writes the first state and the object's size, mass,
  inertia and friction into them (per-world model fields); the command offset (:func:`train.randomize.turn`) and
  the perception noise apply every step.

Measured on one H200 (``make bench-train-mjlab``, 4096 worlds, the default corpus's box episodes, the laptop run's
policy), three versions: restarts as a Python loop of the numpy code, then drawn and started on the device for all
worlds at once, then without MuJoCo Warp's ``set_const`` (the object's derived constants written directly,
:func:`train.mjlab_object.rigid_body`):

==========================================  ==========  ==========  =============
env steps/s                                  loop        batched     no set_const
==========================================  ==========  ==========  =============
MuJoCo Warp alone (4 substeps)               173k        173k        152k
this environment                             29k         48k         56k
PPO, plain (no randomisation, no prior)      22k         28k         39k
PPO + randomisations                         20k (+10%)  27k (+7%)   36k (+8%)
PPO + randomisations + AIP + AMP             21k (+7%)   25k (+14%)  36k (+10%)
==========================================  ==========  ==========  =============

(5 PPO iterations per case in the first two columns, 3 in the last; the physics row moved by 12% between machines.)
These were measured on the box episodes alone, one box geom per world, and before :class:`train.mjlab_terms.Worlds`
was shared by mjlab's managers (their terms read a stale copy, doing the same work per step on the wrong episode);
the chairs' six parts and the cylinder slot have not been measured on a GPU.

:class:`MjlabPostTrainEnv` is rsl_rl's ``VecEnv`` over it with :class:`train.post_env.PostTrainEnv`'s observations
and extras, so :mod:`train.aip` trains either. It runs the episodes of one box or one chair, the four tasks of the
default corpus, with the six randomisations (:mod:`train.mjlab_object`: every world's object has the most box parts
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

from features.compute import FeatureConfig
from physicalize.rollout import SUBSTEPS
from pipeline.errors import InputError
from pipeline.robot import NUM_JOINTS
from pipeline.scene import (
    IMPRATIO,
    PHYSICS_TIMESTEP,
    SceneObject,
    build_spec,
)
from train import rewards as R
from train.episodes import Episode
from train.mjlab_object import add_object_floor_pairs, entity_spec
from train.mjlab_terms import (
    NoisyJointTargetsCfg,
    Worlds,
    action_rate,
    check_episodes,
    fell,
    interaction,
    interaction_seen,
    joint_limits,
    object_tracking,
    proprio,
    reference_end,
    root_command,
    root_tracking,
    runs_on_mjlab,
    start_episodes,
    termination,
)
from train.post_env import AMP_STATE, PostEnvConfig

DF_START = 2 * NUM_JOINTS + 6 + NUM_JOINTS + 12
"""Where the DF features start in the ``critic`` row ``[proprio (93), root_command (12), df]``."""

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
            links: tuple[str, ...] = FeatureConfig().links) -> ManagerBasedRlEnvCfg:  # fmt: skip
    """The mjlab configuration of ``envs`` worlds over ``worlds``' episodes (module docstring)."""
    profile = worlds.episodes[0].profile
    if any(e.profile != profile for e in worlds.episodes):
        raise InputError(worlds.episodes[0].simulated.robot.source, "actuator_profile", "episodes of two profiles")
    shapes = worlds.shapes  # the object entity has the most parts any episode needs (train.mjlab_object)
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

    policy = {"proprio": obs(proprio, None, history), "root_command": obs(root_command, w, history),
              "df": obs(interaction_seen, lw, history)}  # fmt: skip
    critic = {"proprio": obs(proprio), "root_command": obs(root_command, w), "df": obs(interaction, lw)}
    frames = int(worlds.frames.max())
    return ManagerBasedRlEnvCfg(
        decimation=SUBSTEPS,
        scene=SceneCfg(
            num_envs=envs,
            entities={"robot": robot, "object": obj},
            spec_fn=lambda spec: add_object_floor_pairs(spec, scene_object),
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
    """rsl_rl's ``VecEnv`` over the mjlab environment, with :class:`train.post_env.PostTrainEnv`'s observations
    (``policy`` windows, ``critic`` current step) and extras (``style``, ``time_outs``, ``log``)."""

    def __init__(self, episodes: list[Episode], history: int, config: PostEnvConfig = PostEnvConfig(),
                 device: str = "cuda"):  # fmt: skip
        check_device(device)
        self.worlds = Worlds(episodes, config.envs, config.randomization, config.seed, device)
        self.env = ManagerBasedRlEnv(env_cfg(self.worlds, config.envs, history, config.weights), device=device)
        self.obs, _ = self.env.reset()
        self.cfg, self.device = config, torch.device(device)
        self.num_envs, self.num_actions = config.envs, NUM_JOINTS
        self.max_episode_length = int(self.worlds.frames.max())
        self.weights = {k: v for k, v in config.weights.terms().items() if k in self.env.reward_manager.active_terms}

    @property
    def episode_length_buf(self) -> torch.Tensor:
        return self.env.episode_length_buf

    def get_observations(self) -> TensorDict:
        return TensorDict({k: self.obs[k] for k in ("policy", "critic")}, batch_size=[self.num_envs])

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        before = self.obs["critic"][:, AMP_STATE]
        obs, reward, terminated, time_outs, _ = self.env.step(actions)
        critic = obs["critic"]
        style = {"df": critic[:, DF_START:], "transition": torch.cat([before, critic[:, AMP_STATE]], 1)}
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
