"""Layer 3 of the physicalize teacher: a learned residual on top of the whole-body QP controller.

At control frame ``t`` the base controller (:class:`physicalize.wbc.WholeBodyController`) gives the
joint targets ``u_base``; the residual policy ``pi`` adds a bounded correction::

    u = u_base + s * clip(a, -1, 1),      a = pi(o_t)      (s = ResidualConfig.scale, rad)

and ``u`` is what the position actuators hold for the next 4 physics steps (and what the dataset
records as ``action``). The observation ``o_t`` (:func:`observe`, all in the current pelvis frame
``(p, R)``) is

* state: joint ``q``, ``dq``, projected gravity ``R^T [0 0 -1]``, root angular velocity (body
  frame), root height ``p_z``, and the base targets relative to the state ``u_base - q``;
* reference look-ahead for ``k`` in ``{0} + lookahead`` (frames, clamped to the clip): joint
  ``q*_{t+k}``, root position ``R^T (p*_{t+k} - p)`` and orientation ``R^T R*_{t+k}`` (first two
  columns, the 6-D rotation);
* the first free object's pose relative to the pelvis (position, 6-D rotation) and a presence flag
  (zeros without an object), the phase ``t / (T - 1)`` and the reference's stance flags.

Reward per step (after the hold, against reference frame ``t + 1``), exp kernels ``k(e, s) = exp(-e^2/s^2)``::

    r = w_q k(|q - q*|) + w_p k(|p - p*|) + w_R k(angle(R^T R*)) + w_f k(sqrt(sum_feet |x_f - x*_f|^2))
        + w_o k(|x_o - x*_o|) + w_alive - w_rate |a - a_prev|^2

(``w_o`` term is 1 without an object). An episode ends on a fall (:func:`pipeline.terms.fall.fallen`,
a termination) or at the clip's end / ``max_episode_frames`` (a time-out, bootstrapped by PPO).
Episodes start at random frames of the clip from the reference state (the velocity: median of the
next 5 reference frames), objects at their reference pose at rest.

:class:`ResidualEnv` is an ``rsl_rl.env.VecEnv`` (rsl-rl-lib 5.4.2: observations are a TensorDict
with the group ``policy``; ``extras["time_outs"]``) over ``num_envs`` ``MjData`` of one model, each
with its own controller; it runs on the CPU. :func:`train_residual` trains it with rsl-rl's PPO
(``OnPolicyRunner``) and writes a checkpoint (actor weights with the observation normaliser, config,
training figures); :meth:`ResidualPolicy.load` rebuilds the deterministic policy (mean action),
a callable ``(data, ref, t, base_action) -> action`` for :func:`physicalize.rollout.simulate`.
"""

from __future__ import annotations

import contextlib
import io
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import mujoco
import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from physicalize.problem import tracking_problem
from physicalize.reference import Reference
from physicalize.rollout import initial_state
from physicalize.wbc import WholeBodyController
from pipeline.clip import RobotClip
from pipeline.robot import (
    FOOT_BODIES,
    FREE_NQ,
    JOINTS_QPOS,
    JOINTS_QVEL,
    NQ_ROBOT,
    NUM_JOINTS,
    ROOT_ANG_VEL,
    ROOT_POS,
    ROOT_QUAT,
)
from pipeline.rotations import quat_mat
from pipeline.stage.atomic import write_torch_atomic
from pipeline.terms.fall import fallen
from pipeline.terms.layout import SUBSTEPS
from pipeline.terms.observations import rot6

FORMAT = "lessmimic-residual-v1"


@dataclass(frozen=True)
class ResidualConfig:
    """Action scale, observation, reward and PPO settings (all stored in the checkpoint; a checkpoint
    written before a field existed loads with its default)."""

    scale: float = 0.05  # rad per unit of clipped policy output
    lookahead: tuple[int, ...] = (1, 2, 5, 10)  # reference frames ahead observed (besides the current one)
    sigma_joint: float = 0.5  # rad (norm over the 29 joints)
    sigma_root_pos: float = 0.1  # m
    sigma_root_rot: float = 0.3  # rad
    sigma_feet: float = 0.1  # m
    sigma_object: float = 0.15  # m
    w_joint: float = 0.5
    w_root_pos: float = 0.5
    w_root_rot: float = 0.5
    w_feet: float = 0.5
    w_object: float = 0.5
    w_alive: float = 1.0
    w_action_rate: float = 0.01
    max_episode_frames: int = 250
    start_margin: int = 10  # episodes start at frames [0, T - start_margin)
    reference: str = "feasible"  # tracked reference (physicalize.problem.tracking_problem)
    profile: str = "mjlab"
    num_steps_per_env: int = 24
    hidden_dims: tuple[int, ...] = (256, 128)
    init_std: float = 0.5
    learning_rate: float = 1e-3
    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    gamma: float = 0.99
    lam: float = 0.95
    entropy_coef: float = 0.005
    clip_param: float = 0.2
    value_loss_coef: float = 1.0
    max_grad_norm: float = 1.0
    schedule: str = "adaptive"  # rsl-rl's learning-rate schedule (adapted to desired_kl)
    desired_kl: float = 0.01
    activation: str = "elu"  # of the actor's and the critic's MLPs

    @classmethod
    def from_dict(cls, d: dict) -> ResidualConfig:
        names = {f.name for f in fields(cls)}
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items() if k in names})


def observe(d: mujoco.MjData, ref: Reference, t: int, base_action: np.ndarray, cfg: ResidualConfig) -> np.ndarray:
    """The policy observation ``o_t`` (float32; layout in the module docstring). The robot is the
    model's first tree (qpos 0..35); the first free object, if any, is at qpos 36..42."""
    T = ref.frames
    t = min(max(t, 0), T - 1)
    p, R = d.qpos[:3], quat_mat(d.qpos[3:7])
    q = d.qpos[JOINTS_QPOS]
    parts = [q, d.qvel[JOINTS_QVEL], R.T @ np.array([0.0, 0.0, -1.0]), d.qvel[ROOT_ANG_VEL], p[2:3], base_action - q]
    for k in (0, *cfg.lookahead):
        r = ref.qpos[min(t + k, T - 1)]
        parts += [r[JOINTS_QPOS], R.T @ (r[ROOT_POS] - p), rot6(R.T @ quat_mat(r[ROOT_QUAT]))]
    if d.qpos.shape[0] >= NQ_ROBOT + FREE_NQ:
        o = d.qpos[NQ_ROBOT : NQ_ROBOT + FREE_NQ]
        parts += [R.T @ (o[:3] - p), rot6(R.T @ quat_mat(o[3:7])), np.ones(1)]
    else:
        parts.append(np.zeros(10))
    parts += [np.array([t / max(T - 1, 1)]), ref.stance[t].astype(float)]
    return np.concatenate(parts).astype(np.float32)


def _kernel(err: float, sigma: float) -> float:
    return float(np.exp(-((err / sigma) ** 2)))


def _actor_cfg(cfg: ResidualConfig) -> dict:
    return {
        "class_name": "MLPModel",
        "hidden_dims": list(cfg.hidden_dims),
        "activation": cfg.activation,
        "obs_normalization": True,
        "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": cfg.init_std, "std_type": "scalar"},
    }


class ResidualEnv(VecEnv):
    """``num_envs`` copies of one clip's tracking problem (CPU, one ``MjData`` and controller each)."""

    def __init__(
        self,
        scene,
        ref: Reference,
        objects: dict[str, np.ndarray],
        num_envs: int,
        seed: int,
        cfg: ResidualConfig = ResidualConfig(),
    ):
        if ref.frames < 3:
            raise ValueError(f"a residual needs a clip of at least 3 frames, got {ref.frames}")
        self.scene, self.ref, self.objects, self.cfg = scene, ref, objects, cfg
        m = self.model = scene.model
        self.num_envs, self.num_actions, self.device = num_envs, NUM_JOINTS, "cpu"
        self.max_episode_length = min(cfg.max_episode_frames, ref.frames - 1)
        self.episode_length_buf = torch.zeros(num_envs, dtype=torch.long)
        self.rng = np.random.default_rng(seed)
        self.datas = [mujoco.MjData(m) for _ in range(num_envs)]
        self.wbcs = [WholeBodyController(m, scene.profile) for _ in range(num_envs)]
        self.feet = [m.body(b).id for b in FOOT_BODIES]
        self.torso = m.body("torso_link").id
        self.obj = next(iter(scene.object_qpos_adr.items()), None)  # (name, qpos address) of the first free object
        self.t, self.start = np.zeros(num_envs, int), np.zeros(num_envs, int)
        self.base, self.prev = np.zeros((num_envs, NUM_JOINTS)), np.zeros((num_envs, NUM_JOINTS))
        self.episodes: list[tuple[int, int, bool]] = []  # (start frame, frames lived, fell)
        self.steps, self.reward_sum = 0, 0.0
        self.obs = np.stack([self._reset(i) for i in range(num_envs)])
        self.obs_dim = self.obs.shape[1]

    def _reset(self, i: int) -> np.ndarray:
        s = int(self.rng.integers(0, max(1, self.ref.frames - self.cfg.start_margin)))
        d = self.datas[i]
        d.qpos[:], d.qvel[:] = initial_state(self.scene, self.ref, self.objects, s)
        d.ctrl[:] = 0.0
        mujoco.mj_forward(self.model, d)
        self.t[i] = self.start[i] = s
        self.episode_length_buf[i] = 0
        self.prev[i] = 0.0
        return self._plan(i)

    def _plan(self, i: int) -> np.ndarray:
        d, t = self.datas[i], int(self.t[i])
        self.base[i] = self.wbcs[i].solve(d, self.ref.target(t)).action
        return observe(d, self.ref, t, self.base[i], self.cfg)

    def _reward(self, d: mujoco.MjData, t: int, a: np.ndarray, a_prev: np.ndarray) -> float:
        cfg, r = self.cfg, self.ref.qpos[t]
        e_rot = 2.0 * np.arccos(min(1.0, abs(float(np.dot(d.qpos[3:7], r[ROOT_QUAT])))))
        e_feet = np.sqrt(
            sum(float(np.sum((d.xpos[f] - self.ref.foot_pos[t, k]) ** 2)) for k, f in enumerate(self.feet))
        )
        rew = (
            cfg.w_joint * _kernel(np.linalg.norm(d.qpos[JOINTS_QPOS] - r[JOINTS_QPOS]), cfg.sigma_joint)
            + cfg.w_root_pos * _kernel(np.linalg.norm(d.qpos[:3] - r[ROOT_POS]), cfg.sigma_root_pos)
            + cfg.w_root_rot * _kernel(e_rot, cfg.sigma_root_rot)
            + cfg.w_feet * _kernel(e_feet, cfg.sigma_feet)
            + cfg.w_alive
            - cfg.w_action_rate * float(np.sum((a - a_prev) ** 2))
        )
        if self.obj is not None:
            name, adr = self.obj
            rew += cfg.w_object * _kernel(
                np.linalg.norm(d.qpos[adr : adr + 3] - self.objects[name][t, :3]), cfg.sigma_object
            )
        else:
            rew += cfg.w_object
        return rew

    def get_observations(self) -> TensorDict:
        return TensorDict({"policy": torch.from_numpy(self.obs.copy())}, batch_size=[self.num_envs])

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Apply ``u = u_base + s clip(a)`` for one control period in every env; reset finished ones."""
        a = np.clip(actions.detach().cpu().numpy().astype(np.float64), -1.0, 1.0)
        n, T = self.num_envs, self.ref.frames
        rew, done, timeout = np.zeros(n, np.float32), np.zeros(n, bool), np.zeros(n, bool)
        for i in range(n):
            d = self.datas[i]
            d.ctrl[:] = self.base[i] + self.cfg.scale * a[i]
            for _ in range(SUBSTEPS):
                mujoco.mj_step(self.model, d)
            mujoco.mj_forward(self.model, d)
            t = self.t[i] = self.t[i] + 1
            self.episode_length_buf[i] += 1
            rew[i] = self._reward(d, t, a[i], self.prev[i])
            self.prev[i] = a[i]
            fell = fallen(d, self.ref.qpos[t, 2], self.torso)
            timeout[i] = not fell and (t >= T - 1 or int(self.episode_length_buf[i]) >= self.max_episode_length)
            done[i] = fell or timeout[i]
            if done[i]:
                self.episodes.append((int(self.start[i]), int(self.episode_length_buf[i]), bool(fell)))
                self.obs[i] = self._reset(i)
            else:
                self.obs[i] = self._plan(i)
        self.steps += n
        self.reward_sum += float(rew.sum())
        extras = {"time_outs": torch.from_numpy(timeout), "log": {"/residual/falls": float((done & ~timeout).sum())}}
        return self.get_observations(), torch.from_numpy(rew), torch.from_numpy(done), extras


def _train_cfg(cfg: ResidualConfig) -> dict:
    """rsl-rl-lib 5.4.2 OnPolicyRunner configuration (PPO, MLP actor/critic with observation normalisation)."""
    return {
        "num_steps_per_env": cfg.num_steps_per_env,
        "save_interval": 10**9,
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "algorithm": {
            "class_name": "PPO",
            "learning_rate": cfg.learning_rate,
            "num_learning_epochs": cfg.num_learning_epochs,
            "num_mini_batches": cfg.num_mini_batches,
            "gamma": cfg.gamma,
            "lam": cfg.lam,
            "entropy_coef": cfg.entropy_coef,
            "clip_param": cfg.clip_param,
            "value_loss_coef": cfg.value_loss_coef,
            "max_grad_norm": cfg.max_grad_norm,
            "schedule": cfg.schedule,
            "desired_kl": cfg.desired_kl,
            "rnd_cfg": None,
            "symmetry_cfg": None,
        },
        "actor": _actor_cfg(cfg),
        "critic": {
            "class_name": "MLPModel",
            "hidden_dims": list(cfg.hidden_dims),
            "activation": cfg.activation,
            "obs_normalization": True,
        },
    }


def train_residual(
    clip: RobotClip,
    iterations: int,
    num_envs: int,
    seed: int,
    out_path: str | Path,
    *,
    config: ResidualConfig = ResidualConfig(),
    verbose: bool = False,
) -> Path:
    """Train the residual on one retargeted ``clip`` with PPO (``iterations`` x ``num_envs`` x
    ``config.num_steps_per_env`` env steps; torch on 1 thread, seeded) and write the checkpoint to
    ``out_path`` (atomically). Deterministic for a seed on one machine."""
    from rsl_rl.runners import OnPolicyRunner

    torch.manual_seed(seed)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # measured 3.4x faster than 2 threads on a loaded 2-core machine (FIELD-NOTES)
    try:
        scene, ref, objects, _ = tracking_problem(clip, config.profile, config.reference)
        env = ResidualEnv(scene, ref, objects, num_envs, seed, config)
        with contextlib.redirect_stdout(io.StringIO()):  # the runner prints its models
            runner = OnPolicyRunner(env, _train_cfg(config), log_dir=None, device="cpu")
        history, t0 = [], time.perf_counter()
        for it in range(iterations):
            n_ep, steps, rsum = len(env.episodes), env.steps, env.reward_sum
            runner.learn(1)
            ended = env.episodes[n_ep:]
            row = {
                "iteration": it,
                "reward_per_step": (env.reward_sum - rsum) / max(env.steps - steps, 1),
                "episodes": len(ended),
                "mean_episode_frames": float(np.mean([e[1] for e in ended])) if ended else None,
                "fall_frac": float(np.mean([e[2] for e in ended])) if ended else None,
            }
            history.append(row)
            if verbose:
                print(
                    " ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()), flush=True
                )
        seconds = time.perf_counter() - t0
        actor = runner.alg.get_policy()
        ckpt = {
            "format": FORMAT,
            "config": {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(config).items()},
            "obs_dim": env.obs_dim,
            "actor_state_dict": actor.state_dict(),
            "critic_state_dict": runner.alg.critic.state_dict(),
            "training": {
                "source": clip.source,
                "frames": ref.frames,
                "iterations": iterations,
                "num_envs": num_envs,
                "seed": seed,
                "env_steps": env.steps,
                "seconds": seconds,
                "history": history,
            },
        }
    finally:
        torch.set_num_threads(threads)
    out = Path(out_path)
    write_torch_atomic(out, ckpt)
    return out


class ResidualPolicy:
    """A trained residual, deterministic (the Gaussian's mean): ``policy(data, ref, t, base_action) -> action``."""

    def __init__(self, actor: torch.nn.Module, config: ResidualConfig, obs_dim: int, training: dict):
        self.actor, self.cfg, self.obs_dim, self.training = actor.eval(), config, obs_dim, training

    @classmethod
    def load(cls, path: str | Path) -> ResidualPolicy:
        """Rebuild the actor (with its observation normaliser) from a :func:`train_residual` checkpoint."""
        from rsl_rl.models import MLPModel

        ck = torch.load(Path(path), map_location="cpu", weights_only=True)
        if not isinstance(ck, dict) or ck.get("format") != FORMAT:
            raise ValueError(f"{path}: not a {FORMAT} checkpoint")
        cfg = ResidualConfig.from_dict(ck["config"])
        spec = _actor_cfg(cfg)
        spec.pop("class_name")
        dummy = TensorDict({"policy": torch.zeros(1, ck["obs_dim"])}, batch_size=[1])
        actor = MLPModel(dummy, {"actor": ["policy"]}, "actor", NUM_JOINTS, **spec)
        actor.load_state_dict(ck["actor_state_dict"])
        return cls(actor, cfg, ck["obs_dim"], ck.get("training", {}))

    def correction(self, obs: np.ndarray) -> np.ndarray:
        """``clip(pi(o), -1, 1)`` for a batch of observations (n, obs_dim)."""
        with torch.inference_mode():
            a = self.actor(TensorDict({"policy": torch.as_tensor(obs, dtype=torch.float32)}, batch_size=[obs.shape[0]]))
        return np.clip(a.numpy().astype(np.float64), -1.0, 1.0)

    def __call__(self, data: mujoco.MjData, ref: Reference, t: int, base_action: np.ndarray) -> np.ndarray:
        obs = observe(data, ref, t, base_action, self.cfg)
        if obs.shape[0] != self.obs_dim:
            raise ValueError(f"observation has {obs.shape[0]} values, the checkpoint's policy takes {self.obs_dim}")
        return base_action + self.cfg.scale * self.correction(obs[None])[0]
