"""A Python replica of the LessMimic web viewer's physics and control loop, running an exported ``lessmimic-demo``
policy folder on one of our corpus episodes and scoring it with our own task rules.

Viewer facts ("facts N") were read from its public repository (LessMimic/lessmimic.github.io at 94a2c33,
``humanoid-policy-viewer/``: 1 the loop, ``src/simulation/main.js``, ``mujocoUtils.js``, ``Demo.vue``; 2 the
distance grids, ``sdfHelper.js``; 3 the scene, ``public/examples/scenes/g1/g1_interaction.xml``; 4 the runner and
encoder, ``interactionPolicyRunner.js``, ``latent_encoder.onnx``); it has no licence, so facts only, no code. Where
the viewer has nothing to say (the initial state, objects, target, scoring) the loop is our CPU environment's
(:mod:`train.envs.cpu.env`), its slot reused.

**Physics** (facts 1 "Timestep and decimation", 3 "Simulation options"): our G1 scene
(:func:`pipeline.scene.build_scene`: the same MJCF, collision set, armature and objects as our environment) with the
viewer's ``<option>``, MuJoCo's default: 2 ms step, Euler, pyramidal cones, ``impratio`` 1; 10 substeps per 50 Hz
policy step. Every robot joint gets passive damping 0.2, frictionloss 0.1 and ``solimplimit`` (0.97, 0.995, 0.001)
(facts 3 "Robot joint defaults"); the armature is already the viewer's (facts 3 "Armature per class"). The objects
keep our masses and frictions: the replica changes the physics step, the PD law and the distance field, not them.

**Control** (facts 1 "PD law"): ``<motor>`` actuators, gear 1, ``ctrlrange`` +-:data:`CTRL_LIMIT` (the effort limits,
with the hip roll at the viewer's 88 N m, facts 3 "Actuators"), driven by the explicit PD law recomputed in Python
before every substep, ``ctrl = clip(kp (a - q) - kd qd, ctrlrange)``, ``qfrc_applied`` zeroed; ``a`` the policy's
action clipped to +-``action_clip``, absolute targets (no scale, no default offset). ``kp``/``kd`` are the json's
``stiffness``/``damping`` (as float32, mujocoUtils.js:281-282) and must equal the ``lessmimic_demo`` profile's
(:func:`pipeline.robot.actuator_profile`), else a one-line :class:`InputError`.

**Observation** (facts 1 "Root state", "SDF query bodies", "Runner details"; the export's fixed format): read right
after the last ``mj_step`` (so the bodies' ``xpos``/``xquat`` are one substep stale, as in the viewer); histories of
:attr:`DemoLoopConfig.history` steps, newest first, zero-filled at reset, the last action pushed before inference:

* ``proprio`` (465): 5 x (q (29), 0.05 qd (29)), 5 x gravity in the root frame (3), 5 x the free joint's
  body-frame angular velocity ``qvel[3:6]`` (3), 5 x the last clipped action (29);
* ``movement_goal`` (12): with ``H`` the root's yaw: ``H^-1 (p* - p)`` with z = 0; the first two columns of
  ``H^-1 R*`` in row-major order ``r00, r01, r10, r11, r20, r21``; ``H^-1`` of the target's displacement since the
  previous policy step (not divided by dt; zero at the first step: the viewer's target starts at rest), z = 0.
  The target ``(p*, R*)`` is the episode's simulated root at the frame our environment commands
  (``EnvSlot.command``: 1 s ahead, the last frame near the end);
* ``task_condition`` (2): ``[v, v]``, :data:`TASK_CONDITION` (facts 1 "Target root pose and task condition");
* ``interaction_field`` (320): 5 x the encoder's latent of ``[7 distances, 7 x 3 body-frame gradients]``
  (:mod:`train.export.voxel_field`), divided by ``|latent| + 1e-8`` (facts 4).

**Start and end**: the episode's first simulated frame (as our evaluation; the viewer's standing zero pose is in no
episode), objects at rest on their track's first pose; a fall (:func:`pipeline.terms.fall.fallen`) or the last frame
ends it, scored by :class:`train.mdp.tasks.TaskMeter` on the environment's ``EnvSlot.facts``. Any episode runs, of any
actuator profile (only its initial state is used); the result notes the profile.
"""

from __future__ import annotations

import json
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from pipeline.errors import InputError
from pipeline.robot import EFFORT_LIMIT, G1_JOINT_NAMES, JOINTS_QPOS, NUM_JOINTS, actuator_profile
from pipeline.rotations import quat_mat
from pipeline.terms.interaction import demo_features
from pipeline.terms.layout import ROOT_HORIZON_S, TASK_CONDITION
from train.envs.cpu.env import EnvConfig, EnvSlot, cached_field
from train.episodes import Episode
from train.export.demo import ACTION_CLIP, DEMO_FILES, DEMO_PROFILE, JOINT_VEL_SCALE, LATENT, viewer_state
from train.export.runtime import cpu_session
from train.export.voxel_field import body_frame, build_grid, query_objects
from train.mdp.tasks import Rules

CONFIG_FILE, ENCODER_FILE, POLICY_FILE = DEMO_FILES  # the export's files (train.export.demo)
LATENT_EPS = 1e-8  #: the latent is divided by ``|latent| + 1e-8`` (facts 4, runner:290-295)
#: The viewer's ``ctrlrange`` per joint (facts 3 "Actuators"): the effort limits, the hip roll at 88 N m (its joint's
#: 139 N m ``actuatorfrcrange`` never binds).
CTRL_LIMIT = np.where(["hip_roll" in j for j in G1_JOINT_NAMES], 88.0, EFFORT_LIMIT)


@dataclass(frozen=True)
class DemoLoopConfig:
    """The viewer's loop (facts 1, 3): 2 ms steps x 10, actions clipped to 10, its joint damping, frictionloss, limits,
    MuJoCo's default pyramidal cone and ``impratio``; distances up to 1 m on 40^3 grids padded by 1 m (facts 2); our
    root command's 1 s horizon; our task rules."""

    timestep: float = 0.002
    decimation: int = 10
    action_clip: float = ACTION_CLIP
    joint_damping: float = 0.2
    frictionloss: float = 0.1
    joint_solimplimit: tuple[float, float, float] = (0.97, 0.995, 0.001)
    max_distance: float = 1.0
    grid: int = 40
    padding: float = 1.0
    history: int = 5
    horizon_s: float = ROOT_HORIZON_S
    cone: str = "pyramidal"
    impratio: float = 1.0
    distance: str = "grid"  # "exact": our exact fields instead of the voxel grids (to measure what the grids cost)
    rules: Rules = field(default_factory=Rules)

    def __post_init__(self):
        if self.distance not in ("grid", "exact"):
            raise ValueError(f"distance must be 'grid' or 'exact', got {self.distance!r}")


@dataclass(frozen=True, eq=False)
class DemoExport:
    """An export folder, read and checked: policy joint order, PD gains (float32, as the viewer), query bodies."""

    folder: Path
    joint_names: tuple[str, ...]
    kp: np.ndarray
    kd: np.ndarray
    query_bodies: tuple[str, ...]

    @classmethod
    def load(cls, folder: str | Path, cfg: DemoLoopConfig = DemoLoopConfig()) -> DemoExport:
        """The folder's json, checked against the loop (module docstring); a one-line :class:`InputError` else."""
        folder = Path(folder)
        for name in (CONFIG_FILE, POLICY_FILE, ENCODER_FILE):
            if not (folder / name).is_file():
                raise InputError(folder / name, "file", "missing: not a lessmimic-demo export folder")
        path = folder / CONFIG_FILE
        try:
            c = json.loads(path.read_text())
            names = tuple(c["policy_joint_names"])
            kp, kd = (np.asarray(c[k], dtype=np.float32).astype(float) for k in ("stiffness", "damping"))
            bodies = tuple(c["sdf"]["query_body_names"])
            expect = {
                "history_length": (c["history_length"], cfg.history),
                "action_clip": (c["action_clip"], cfg.action_clip),
                "sdf.max_valid_distance": (c["sdf"]["max_valid_distance"], cfg.max_distance),
                "control_type": (c["control_type"], "joint_position"),
            }
        except (ValueError, KeyError, TypeError) as exc:
            raise InputError(path, "json", f"unreadable or incomplete ({type(exc).__name__}: {exc})") from None
        for key, (got, want) in expect.items():
            if got != want:
                raise InputError(path, key, f"{got!r}, the loop runs {want!r}")
        if sorted(names) != sorted(G1_JOINT_NAMES) or kp.shape != (NUM_JOINTS,) or kd.shape != (NUM_JOINTS,):
            raise InputError(path, "policy_joint_names", "not the G1's 29 joints with 29 gains each")
        profile, order = actuator_profile(DEMO_PROFILE), [G1_JOINT_NAMES.index(n) for n in names]
        for key, got, want in (("stiffness", kp, profile.kp[order]), ("damping", kd, profile.kd[order])):
            if not np.allclose(got, want):
                i = int(np.flatnonzero(~np.isclose(got, want))[0])
                raise InputError(path, key, f"{names[i]} {got[i]:g}, the {DEMO_PROFILE} profile's is {want[i]:g}")
        return cls(folder, names, kp, kd, bodies)


class DemoPolicy:
    """The folder's two ONNX models in onnxruntime (:func:`train.export.runtime.cpu_session`: CPU, one thread, all
    graph optimisations, as the viewer's WASM runtime, facts 1 "Runner details")."""

    def __init__(self, folder: str | Path, cfg: DemoLoopConfig = DemoLoopConfig()):
        self.export, self.cfg = DemoExport.load(folder, cfg), cfg
        self.policy, self.encoder = (cpu_session(self.export.folder / f) for f in (POLICY_FILE, ENCODER_FILE))
        outputs = [o.name for o in self.policy.get_outputs()]
        self.action_output = next((n for n in outputs if "action" in n), outputs[0])  # runner:414-423

    def latent(self, state: np.ndarray) -> np.ndarray:
        """(64,) the unit latent of the encoder's ``state`` (28,) (facts 4)."""
        z = self.encoder.run(None, {"state": state.astype(np.float32)[None]})[0][0].astype(np.float64)
        return z / (np.linalg.norm(z) + LATENT_EPS)

    def act(self, feeds: dict[str, np.ndarray]) -> np.ndarray:
        """(29,) the policy's raw action (absolute joint targets, policy order)."""
        return self.policy.run([self.action_output], feeds)[0].reshape(-1)[:NUM_JOINTS].astype(np.float64)


class History:
    """The last ``length`` vectors, newest first, zero-filled at reset (the viewer's buffers)."""

    def __init__(self, length: int, width: int):
        self.rows = np.zeros((length, width))

    def push(self, x: np.ndarray) -> None:
        self.rows = np.concatenate([np.asarray(x, dtype=float)[None], self.rows[:-1]])


@dataclass(frozen=True)
class ViewerState:
    """The viewer's reads (facts 1 "Root state", "SDF query bodies"); joints in policy order, ``body_*`` the query
    bodies', ``objects`` (M, 7) the objects' ``xpos``/``xquat``."""

    root_pos: np.ndarray
    root_quat: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    ang_vel: np.ndarray
    body_pos: np.ndarray
    body_quat: np.ndarray
    objects: np.ndarray


def viewer_model(spec: mujoco.MjSpec, cfg: DemoLoopConfig) -> mujoco.MjModel:
    """``spec`` (a :func:`pipeline.scene.build_spec` scene, edited in place) with the viewer's options, motors and
    joint friction (module docstring), compiled."""
    spec.option.timestep, spec.option.integrator = cfg.timestep, mujoco.mjtIntegrator.mjINT_EULER
    spec.option.cone = getattr(mujoco.mjtCone, f"mjCONE_{cfg.cone.upper()}")
    spec.option.impratio = cfg.impratio
    for name in G1_JOINT_NAMES:
        joint = spec.joint(name)
        joint.damping, joint.frictionloss = [cfg.joint_damping, 0.0, 0.0], cfg.frictionloss  # MjSpec: (linear, ...)
        joint.solimp_limit = [*cfg.joint_solimplimit, 0.5, 2.0]  # MuJoCo's default midpoint and power
    for act in spec.actuators:
        limit = float(CTRL_LIMIT[G1_JOINT_NAMES.index(act.target)])
        act.set_to_motor()
        act.biasprm, act.gear = [0.0] * 10, [1.0, 0, 0, 0, 0, 0]
        act.ctrllimited, act.ctrlrange = mujoco.mjtLimited.mjLIMITED_TRUE, [-limit, limit]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
    return spec.compile()


class ViewerSlot(EnvSlot):
    """Our environment's slot for ``episode`` at scale 1 (its initial state, command frames, reference, contact
    sets, facts and meter), simulated with :func:`viewer_model` and stepped with the viewer's PD loop."""

    def __init__(self, episode: Episode, export: DemoExport, cfg: DemoLoopConfig, fields: dict, joint_offset=None):
        super().__init__(episode, 1.0, EnvConfig(root_horizon_s=cfg.horizon_s, rules=cfg.rules), fields)
        self.cfg, self.kp, self.kd = cfg, export.kp, export.kd
        self.scene.profile, self.scene.model = actuator_profile(DEMO_PROFILE), viewer_model(self.scene.spec, cfg)
        m = self.scene.model
        self.data = mujoco.MjData(m)
        qpos = episode.simulated.robot.qpos[0].copy()
        if joint_offset is not None:  # the evaluation's joint noise (train.evaluation.table2._run)
            qpos[JOINTS_QPOS] += joint_offset
        self.set_state(qpos, episode.simulated.qvel[0])
        self.last_facts = self.facts(0)
        joints = [m.joint(n).id for n in export.joint_names]  # the viewer's mapping by name (mujocoUtils.js:638-675)
        self.qadr, self.dadr = m.jnt_qposadr[joints], m.jnt_dofadr[joints]
        self.ctrl_index = np.array([int(np.flatnonzero(m.actuator_trnid[:, 0] == j)[0]) for j in joints])
        self.low, self.high = m.actuator_ctrlrange[self.ctrl_index].T
        root = m.body_jntadr[m.body("pelvis").id]  # the pelvis's free joint
        self.root_qadr, self.root_dadr = m.jnt_qposadr[root], m.jnt_dofadr[root]
        self.query_ids = [m.body(b).id for b in export.query_bodies]
        self.object_ids = [self.scene.object_body_id[o.name] for o in self.objects]
        self.pd = (np.zeros(NUM_JOINTS),) * 3  # the last substep's (q, qd, ctrl)
        self.state = self.read()

    def read(self) -> ViewerState:
        """The viewer's reads of the current ``data``, without a new forward pass."""
        d, r, a = self.data, self.root_qadr, self.root_dadr
        return ViewerState(
            d.qpos[r : r + 3].copy(),
            d.qpos[r + 3 : r + 7].copy(),
            d.qpos[self.qadr].astype(np.float32).astype(float),
            d.qvel[self.dadr].astype(np.float32).astype(float),
            d.qvel[a + 3 : a + 6].copy(),
            d.xpos[self.query_ids].copy(),
            d.xquat[self.query_ids].copy(),
            np.concatenate([d.xpos[self.object_ids], d.xquat[self.object_ids]], axis=1).reshape(-1, 7),
        )

    def step(self, action: np.ndarray) -> None:
        """Hold the joint targets ``action`` (policy order) for ``decimation`` substeps of the PD law, read the
        viewer's state, then update the kinematics, the fall test and the meter as ``EnvSlot.step`` does."""
        m, d = self.scene.model, self.data
        for _ in range(self.cfg.decimation):
            q, qd = d.qpos[self.qadr].copy(), d.qvel[self.dadr].copy()
            tau = np.clip(self.kp * (action - q) + self.kd * (0.0 - qd), self.low, self.high)
            d.ctrl[self.ctrl_index] = tau
            d.qfrc_applied[:] = 0.0
            mujoco.mj_step(m, d)
        self.pd = (q, qd, d.ctrl[self.ctrl_index].copy())
        self.state = self.read()
        self.advance(action)


def movement_goal(state: ViewerState, target: np.ndarray, displacement: np.ndarray) -> np.ndarray:
    """(12,) the viewer's movement goal (module docstring) for the target root ``target`` (7,) that moved by
    ``displacement`` (3,) since the previous policy step."""
    R = quat_mat(state.root_quat)
    yaw = np.arctan2(R[1, 0], R[0, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    inv = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # H^-1
    dpos, vel = inv @ (target[:3] - state.root_pos), inv @ displacement
    dpos[2] = vel[2] = 0.0
    rot = (inv @ quat_mat(target[3:7] / np.linalg.norm(target[3:7])))[:, :2].reshape(-1)  # r00 r01 r10 r11 r20 r21
    return np.concatenate([dpos, rot, vel])


class DemoLoop:
    """One episode of the replica: :meth:`step` runs one policy step; :attr:`feeds` keeps the last inputs fed."""

    def __init__(self, policy: DemoPolicy, episode: Episode, caches: dict | None = None, joint_offset=None):
        cfg, caches = policy.cfg, caches if caches is not None else {}
        if abs(episode.fps * cfg.timestep * cfg.decimation - 1.0) > 1e-6:
            raise InputError(episode.simulated.robot.source, "fps", f"{episode.fps:g}, the loop steps at 50 Hz")
        self.policy, self.cfg = policy, cfg
        fields, grids = caches.setdefault("fields", {}), caches.setdefault("grids", {})
        self.slot = ViewerSlot(episode, policy.export, cfg, fields, joint_offset)
        self.grids = []
        for o in self.slot.objects:
            key = (repr(o.geometry), cfg.grid, cfg.padding, cfg.max_distance)
            if key not in grids:
                grids[key] = build_grid(o.geometry, cached_field(fields, o), cfg.grid, cfg.padding, cfg.max_distance)
            self.grids.append(grids[key])
        h, n = cfg.history, NUM_JOINTS
        self.joints, self.gravity, self.ang_vel = History(h, 2 * n), History(h, 3), History(h, 3)
        self.actions, self.latents = History(h, n), History(h, LATENT)
        self.last_action = np.zeros(n)
        self.condition = np.full((1, 2), TASK_CONDITION[episode.task], np.float32)
        self.prev_target = self.target()
        self.feeds: dict[str, np.ndarray] = {}

    def target(self) -> np.ndarray:
        """(7,) the commanded root: the simulated root at our environment's command frame."""
        sim = self.slot.episode.simulated
        return sim.robot.qpos[self.slot.command[min(self.slot.t, sim.frames - 1)], :7].copy()

    def interaction_state(self) -> np.ndarray:
        """(28,) the encoder's input: the query bodies' distances, then their body-frame gradients (facts 2)."""
        s = self.slot.state
        if self.cfg.distance == "exact":  # the training environment's field (train.envs.cpu.env.InteractionEnv.observe)
            near = self.slot.fields.query_links(s.body_pos[None], s.objects[None])
            rot = np.stack([quat_mat(q) for q in s.body_quat])
            return viewer_state(demo_features(near.phi[0], near.grad[0], rot, self.cfg.max_distance).reshape(-1))
        d, g = query_objects(self.grids, s.objects, s.body_pos, self.cfg.max_distance)
        return np.concatenate([d, body_frame(g, s.body_quat).reshape(-1)])

    def step(self) -> bool:
        """One policy step (module docstring); True when the episode is over."""
        s, cfg = self.slot.state, self.cfg
        target = self.target()
        displacement, self.prev_target = target[:3] - self.prev_target[:3], target
        self.actions.push(self.last_action)  # pushed before inference (runner:325, 430)
        self.joints.push(np.concatenate([s.q, JOINT_VEL_SCALE * s.qd]))
        self.gravity.push(quat_mat(s.root_quat).T @ np.array([0.0, 0.0, -1.0]))
        self.ang_vel.push(s.ang_vel)
        self.latents.push(self.policy.latent(self.interaction_state()))
        parts = (self.joints, self.gravity, self.ang_vel, self.actions)
        self.feeds = {
            "proprio": np.concatenate([p.rows.ravel() for p in parts])[None].astype(np.float32),
            "movement_goal": movement_goal(s, target, displacement)[None].astype(np.float32),
            "task_condition": self.condition,
            "interaction_field": self.latents.rows.ravel()[None].astype(np.float32),
        }
        self.last_action = np.clip(self.policy.act(self.feeds), -cfg.action_clip, cfg.action_clip)
        self.slot.step(self.last_action)
        return self.slot.done

    def run(self, max_steps: int | None = None) -> dict:
        """Step to the episode's end, a fall or ``max_steps``; the meter's summary, ``fell`` and the profile."""
        while not self.slot.done and (max_steps is None or self.slot.t < max_steps):
            self.step()
        return {**self.slot.meter.summary(), "fell": self.slot.fell, "episode_profile": self.slot.episode.profile}


def run_demo_episode(
    folder: str | Path, episode: Episode, cfg: DemoLoopConfig = DemoLoopConfig(), max_steps: int | None = None
) -> dict:
    """One episode of the export at ``folder`` in the replica (:meth:`DemoLoop.run`)."""
    return DemoLoop(DemoPolicy(folder, cfg), episode).run(max_steps)


def evaluate_demo_loop(
    folder: str | Path,
    episodes: list[Episode],
    task: str = "PickUp",
    seeds: tuple[int, ...] = (0, 1, 2),
    episodes_per_seed: int = 16,
    cfg: DemoLoopConfig = DemoLoopConfig(),
    joint_noise: float = 0.02,
) -> dict:
    """A Table 2 cell of the export at scale 1.0, drawn as :func:`train.evaluation.table2.evaluate` draws its:
    per seed, ``rng = default_rng(crc32(f"{seed}|{task}|{scale}"))`` picks ``episodes_per_seed`` episodes of the task
    (with replacement when there are fewer), then each one's joint noise ``U(-joint_noise, joint_noise)`` (29) in
    order (the same numbers as table2's, whatever its batch size). The cell: mean over seeds of the success rate
    (Push: the contact rate), ``per_seed``, ``ci95`` (:func:`~train.evaluation.table2.interval95`), episodes, falls."""
    from train.evaluation.table2 import summarize_cell  # scipy and the training stack: only when evaluating

    pool, scale = [e for e in episodes if e.task == task], 1.0
    if not pool:
        raise InputError(None, "task", f"no {task} episode to evaluate")
    policy, caches = DemoPolicy(folder, cfg), {}
    outcomes = []
    for seed in seeds:
        rng = np.random.default_rng(zlib.crc32(f"{seed}|{task}|{scale}".encode()))
        pick = rng.choice(len(pool), episodes_per_seed, replace=len(pool) < episodes_per_seed)
        noise = (rng.uniform(-joint_noise, joint_noise, NUM_JOINTS) for _ in pick)  # drawn in order, as table2
        runs = [DemoLoop(policy, pool[i], caches, offset).run() for i, offset in zip(pick, noise)]
        outcomes.append(runs)
    return {
        **summarize_cell(task, scale, outcomes, seeds),
        "episode_profiles": sorted({r["episode_profile"] for runs in outcomes for r in runs}),
    }
