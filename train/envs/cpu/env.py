"""The interaction environment: ``N`` G1 + object scenes in native MuJoCo on the CPU, 200 Hz physics under
50 Hz control, each running an :class:`~train.episodes.Episode` at an object scale.

**Actions** are the 29 joint position targets of the actuator profile's position actuators (the physicalized
datasets' ``action``), held for :data:`SUBSTEPS` physics steps. **Observations** are the paper's
``o_base`` terms, computed online by the same functions the features stage uses (:mod:`pipeline.terms`,
:mod:`pipeline.distance`), so a dataset row and an environment step agree to the last bit on the same state:

* ``proprio`` (N, 93): :func:`pipeline.terms.observations.proprioception` of the state and the previous action;
* ``root_command`` (N, 12): :func:`pipeline.terms.observations.root_command_to` the episode's command -- its
  simulated root :attr:`EnvConfig.root_horizon_s` ahead (where to go, never how big the object is);
* ``df`` (N, K x 10): u_t per link (:func:`pipeline.terms.interaction.interaction_features`) from the link
  states (:func:`pipeline.terms.link_motion.link_state`) and the objects' exact fields at the scaled geometry.

The policy keeps its own ``l``-step history. Episodes end at the reference's last frame or on a fall
(:func:`pipeline.terms.fall.fallen` against the episode's simulated motion); :class:`train.mdp.tasks.TaskMeter`
scores them. Environments step in ``threads`` worker threads (MuJoCo releases the GIL while it steps).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import mujoco
import numpy as np

from pipeline.contacts import robot_contacts
from pipeline.distance.field import ObjectField, ObjectFields, boxes_query_links
from pipeline.geometry import Chair, MeshGeometry, Primitive
from pipeline.robot import FOOT_BODIES, NQ_ROBOT, NUM_JOINTS, NV_ROBOT
from pipeline.scene import Scene, SceneObject, build_scene, hand_geoms, link_collision_geoms
from pipeline.terms.fall import fallen
from pipeline.terms.interaction import demo_features, interaction_features
from pipeline.terms.layout import DF_LINKS, ROOT_HORIZON_S, SUBSTEPS, TASK_CONDITION, check_contract
from pipeline.terms.link_motion import body_ids, link_motion, link_state
from pipeline.terms.observations import command_frames, demo_command, proprioception, root_command_to
from train.episodes import Episode, check_scale, scaled_objects
from train.mdp import randomize as R
from train.mdp.randomize import Variation
from train.mdp.tasks import Rules, StepFacts, TaskMeter


@dataclass(frozen=True)
class EnvConfig:
    """``links``: the DF links (the observation contract's, :mod:`pipeline.terms.layout`; a policy's own:
    :meth:`for_policy`); ``contract``: the observation contract (:data:`pipeline.terms.layout.CONTRACTS`: the demo's
    DF of its bodies and its command with the task condition); ``root_horizon_s``: how far ahead the root command looks;
    ``threads``: worker threads stepping the environments. The actuator profile is each episode's
    (:attr:`train.episodes.Episode.profile`)."""

    links: tuple[str, ...] = DF_LINKS
    root_horizon_s: float = ROOT_HORIZON_S
    threads: int = 1
    rules: Rules = field(default_factory=Rules)
    contract: str = "lessmimic"

    def __post_init__(self):
        check_contract(self.contract)

    @classmethod
    def for_policy(cls, layout, **kw) -> EnvConfig:
        """The environment that observes what a policy of ``layout`` (:class:`train.policy.PolicyLayout`) reads."""
        return cls(links=tuple(layout.links), contract=layout.contract, **kw)


@dataclass
class Obs:
    proprio: np.ndarray  # (N, 93)
    root_command: np.ndarray  # (N, 12)
    df: np.ndarray  # (N, K * 10)


class History:
    """The last ``l`` observations per environment, ``(N, l, dim)`` per term; an environment's first observation
    fills its whole window (as :class:`pipeline.dataset.windows.WindowDataset` pads an episode's start)."""

    def __init__(self, length: int):
        self.length = length
        self.terms: dict[str, np.ndarray] = {}

    def reset(self, obs: Obs, which: np.ndarray | None = None) -> None:
        for key, value in vars(obs).items():
            if key not in self.terms or which is None:
                self.terms[key] = np.repeat(value[:, None], self.length, axis=1)
            else:
                self.terms[key][which] = np.repeat(value[which, None], self.length, axis=1)

    def push(self, obs: Obs) -> None:
        for key, value in vars(obs).items():
            self.terms[key] = np.concatenate([self.terms[key][:, 1:], value[:, None]], axis=1)


class EnvSlot:
    """One environment: its scene, state, episode and meters."""

    def __init__(self, episode: Episode, scale, cfg: EnvConfig, fields: dict, variation: Variation | None = None):
        self.episode, self.scale, self.variation = episode, check_scale(scale), variation
        sim = episode.simulated
        self.objects = scaled_objects(sim.robot.objects, self.scale)
        if variation is None:
            placed = [SceneObject(o.name, o.geometry, o.physics(), pose=tuple(o.pose[0])) for o in self.objects]
        else:  # the randomisations drawn once per episode (train.mdp.randomize)
            self.objects = tuple(R.vary_shape(o, variation) for o in self.objects)
            placed = [
                SceneObject(o.name, o.geometry, R.object_physics(o, variation), pose=R.placed(o, variation))
                for o in self.objects
            ]
        self.scene: Scene = build_scene(placed, episode.profile)
        m = self.scene.model
        self.data = mujoco.MjData(m)
        self.ids = body_ids(m, cfg.links)
        key = tuple((repr(o.geometry), o.name) for o in self.objects)
        if key not in fields:  # one ObjectFields per object set: environments with the same objects share it
            fields[key] = ObjectFields(tuple(cached_field(fields, o) for o in self.objects))
        self.fields = fields[key]
        self.box_parts = _box_parts(self.objects)
        self.field_keys = {key, *key}  # the cache entries this environment uses (InteractionEnv.reset_one prunes)
        self.command = command_frames(sim.frames, sim.robot.fps, cfg.root_horizon_s)
        torso = link_motion(sim.robot.qpos, sim.qvel, ("torso_link",)).rot[:, 0]
        self.ref_torso_quat = np.array([_mat_quat(R) for R in torso])
        self.torso = m.body("torso_link").id
        self.object_geoms = {g for g in range(m.ngeom) if m.geom_bodyid[g] in set(self.scene.object_body_id.values())}
        self.robot_geoms = {g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] == m.body("pelvis").id}
        self.hand_geoms = set().union(*map(set, hand_geoms(m)))
        self.pelvis_geoms = set(link_collision_geoms(m, "pelvis"))
        feet = {g for b in FOOT_BODIES for g in link_collision_geoms(m, b)}
        self.body_geoms = self.robot_geoms - self.hand_geoms - feet
        links = sim.robot.contact_links
        wrists = [links.index(b) for b in ("left_wrist_yaw_link", "right_wrist_yaw_link") if b in links]
        self.pushing = (
            sim.robot.contacts[:, wrists].any(axis=1)
            if wrists and sim.robot.contacts is not None
            else np.zeros(sim.frames, bool)
        )
        end = self.objects[0].pose[sim.frames - 1, :3] if self.objects else None
        self.meter = TaskMeter(
            episode.task,
            sim.robot.fps,
            cfg.rules,
            track_end=end,
            push_total=int(self.pushing[1:].sum()),
            root_total=control_steps(episode),
        )
        self.t, self.done, self.fell = 0, False, False
        self.last_action = np.zeros(NUM_JOINTS)
        self.set_state(sim.robot.qpos[0], sim.qvel[0])
        if variation is not None:
            free = list(self.scene.object_qpos_adr.values())
            R.perturb_initial_state(self.data.qpos, m.jnt_range[1 : 1 + NUM_JOINTS], free, variation)
            mujoco.mj_forward(m, self.data)
        self.last_facts = self.facts(0)

    def set_state(self, qpos: np.ndarray, qvel: np.ndarray, objects: np.ndarray | None = None) -> None:
        """The robot at ``(qpos, qvel)``; the objects at ``objects`` (nq - 36), else their track at ``t``, at rest."""
        d, m = self.data, self.scene.model
        d.qpos[:NQ_ROBOT], d.qvel[:NV_ROBOT] = qpos, qvel
        if objects is not None:
            d.qpos[NQ_ROBOT:] = objects
        else:
            for o in self.objects:
                if o.name in self.scene.object_qpos_adr:
                    adr = self.scene.object_qpos_adr[o.name]
                    d.qpos[adr : adr + 7] = o.pose[min(self.t, o.frames - 1)]
            d.qvel[NV_ROBOT:] = 0.0
        mujoco.mj_forward(m, d)

    def step(self, action: np.ndarray) -> None:
        """Hold ``action`` for :data:`SUBSTEPS` physics steps, then update the kinematics the observation reads."""
        m, d = self.scene.model, self.data
        d.ctrl[:] = action
        for _ in range(SUBSTEPS):
            mujoco.mj_step(m, d)
        self.advance(action)

    def advance(self, action: np.ndarray) -> None:
        """After the physics steps of ``action``: the kinematics the observation reads, the step count, the fall
        test, the step's facts and the meter (shared by every loop that steps a slot its own way)."""
        m, d = self.scene.model, self.data
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        self.last_action = np.asarray(action, dtype=float).copy()
        self.t += 1
        sim = self.episode.simulated
        k = min(self.t, sim.frames - 1)
        self.fell = fallen(d, sim.robot.qpos[k, 2], self.torso, self.ref_torso_quat[k])
        self.last_facts = self.facts(k)
        self.meter.update(self.last_facts)
        self.done = self.fell or self.t >= control_steps(self.episode)

    def facts(self, k: int) -> StepFacts:
        """What the meter reads at reference frame ``k = min(t, frames - 1)`` (:meth:`advance`).

        ``root_dev_m`` (``R_acc``, :mod:`train.mdp.tasks`) is ``|p_root - q_k[:2]|``, ``q_k`` the episode's simulated
        root at the same frame: the trajectory the root command walks along (:meth:`InteractionEnv.observe` aims it at
        the frame :attr:`EnvConfig.root_horizon_s` ahead, where the root is meant to be *then*; against that point a
        perfect tracker would be a second's walk off). In a chain the episode is the relocated one
        (:func:`train.evaluation.chains.relocated`), so the distance is to the relocated track. A training
        variation's ``command_offset`` is noise on what the policy reads, not the command, and is not applied here.
        Horizontal (x, y), not 3-D: the paper's "Euclidean distance between the root position and the commanded
        trajectory" does not say which; its commanded trajectory is drawn as a path on the floor (the yellow arrow of
        the long-horizon figure), and the root height legitimately departs from the 1.0x reference when the robot sits
        on a scaled chair or crouches to a scaled box; the chains' stray test uses the same distance."""
        m, d = self.scene.model, self.data
        pelvis = hand = body = False
        for c in robot_contacts(m, d, self.robot_geoms):
            if c.other in self.object_geoms:
                pelvis |= c.geom in self.pelvis_geoms
                hand |= c.geom in self.hand_geoms
                body |= c.geom in self.body_geoms
        o = self.objects[0]
        adr = self.scene.object_qpos_adr.get(o.name)
        pos = d.qpos[adr : adr + 3].copy() if adr is not None else o.pose[0, :3]
        return StepFacts(
            object_low=_lowest_point(m, d, self.object_geoms),
            object_pos=pos,
            object_ref=o.pose[k, :3],
            root_z=float(d.qpos[2]),
            root_dev_m=float(np.linalg.norm(d.qpos[:2] - self.episode.simulated.robot.qpos[k, :2])),
            pelvis_on_object=pelvis,
            hand_on_object=hand,
            body_on_object=body,
            reference_pushing=bool(self.pushing[k]),
        )


def control_steps(episode: Episode) -> int:
    """The control steps an episode runs to its reference's last frame (:meth:`EnvSlot.advance` ends it at
    ``t = frames - 1``; at least one): the full length ``R_acc`` divides by."""
    return max(episode.simulated.frames - 1, 1)


def cached_field(cache: dict, o) -> ObjectField:
    """The object's exact field (meshes: warp's closest point, as the features stage queries them), built once."""
    key = (repr(o.geometry), o.name)
    if key not in cache:
        cache[key] = ObjectField.from_geometry(
            o.geometry, o.name, **({"cache": False} if isinstance(o.geometry, MeshGeometry) else {})
        )
    return cache[key]


def _box_parts(objects) -> tuple[np.ndarray, np.ndarray] | None:
    """``(half-extents (P, 3), centres (P, 3))`` of one object made of boxes (a box: P = 1; a chair: its parts), for
    the batched field query; None for anything else."""
    g = objects[0].geometry if len(objects) == 1 else None
    if isinstance(g, Primitive) and g.kind == "box":
        return np.asarray(g.half_extents, dtype=float)[None], np.zeros((1, 3))
    if isinstance(g, Chair):
        parts = g.parts()
        return np.array([p.half_extents for _, p, _ in parts]), np.array([c for _, _, c in parts])
    return None


def _mat_quat(R: np.ndarray) -> np.ndarray:
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, R.ravel())
    return q


def _lowest_point(m: mujoco.MjModel, d: mujoco.MjData, geoms: set[int]) -> float:
    """The lowest point of ``geoms`` (their local bounding boxes, exact for boxes) above the floor [m]."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    low = np.inf
    for g in geoms:
        centre, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
        corners = (centre + signs * half) @ d.geom_xmat[g].reshape(3, 3).T + d.geom_xpos[g]
        low = min(low, float(corners[:, 2].min()))
    return low


class InteractionEnv:
    """``N`` environments (module docstring); :meth:`reset` assigns each an episode and a scale."""

    def __init__(self, config: EnvConfig = EnvConfig()):
        self.cfg = config
        self.slots: list[EnvSlot] = []
        self._fields: dict = {}
        self._pool = ThreadPoolExecutor(config.threads) if config.threads > 1 else None

    @property
    def num_envs(self) -> int:
        return len(self.slots)

    def reset(self, assignments: list[tuple]) -> Obs:
        """Start every environment: ``assignments[i] = (episode, scale)`` or ``(episode, scale, variation)`` (a
        :class:`train.mdp.randomize.Variation`); the observation of the first frame."""
        self.slots = [EnvSlot(e, s, self.cfg, self._fields, *v) for e, s, *v in assignments]
        return self.observe()

    def reset_one(self, i: int, episode: Episode, scale, variation: Variation | None = None) -> None:
        """Restart environment ``i``; the distance fields no environment uses any more are dropped (with a scale
        or a shape drawn per episode, each restart makes new ones: the cache would grow without end)."""
        self.slots[i] = EnvSlot(episode, scale, self.cfg, self._fields, variation)
        used = set().union(*(s.field_keys for s in self.slots))
        for key in [k for k in self._fields if k not in used]:
            del self._fields[key]

    def step(self, actions: np.ndarray) -> tuple[Obs, np.ndarray]:
        """Apply ``actions`` (N, 29) to the running environments (finished ones stand still); ``(obs, done)``."""
        live = [(s, a) for s, a in zip(self.slots, actions) if not s.done]
        if self._pool is not None:
            list(self._pool.map(lambda sa: sa[0].step(sa[1]), live))
        else:
            for s, a in live:
                s.step(a)
        return self.observe(), np.array([s.done for s in self.slots])

    def observe(self) -> Obs:
        """The current observation of every environment (module docstring). The field queries go in batches (a
        query's fixed cost, ~0.1 ms, would otherwise repeat per env): the environments whose object is made of boxes
        (a box, a chair), of whatever drawn size, in one per number of parts; the others one per object set."""
        n = len(self.slots)
        qpos = np.stack([s.data.qpos[:NQ_ROBOT] for s in self.slots])
        qvel = np.stack([s.data.qvel[:NV_ROBOT] for s in self.slots])
        last = np.stack([s.last_action for s in self.slots])
        target_q, target_v = np.zeros((n, 7)), np.zeros((n, 3))
        pos, vel = np.zeros((n, len(self.cfg.links), 3)), np.zeros((n, len(self.cfg.links), 3))
        rot = np.zeros((n, len(self.cfg.links), 3, 3))
        groups: dict[int, list[int]] = {}  # the others, by their object set
        by_parts: dict[int, list[int]] = {}  # boxes and chairs, by their number of parts
        for i, s in enumerate(self.slots):
            sim = s.episode.simulated
            j = s.command[min(s.t, sim.frames - 1)]
            target_q[i], target_v[i] = sim.robot.qpos[j, :7], sim.qvel[j, :3]
            if s.variation is not None:
                target_q[i] = R.perturb_command(target_q[i], s.variation)
            pos[i], rot[i], vel[i] = link_state(s.scene.model, s.data, s.ids)
            if s.box_parts is None:
                groups.setdefault(id(s.fields), []).append(i)
            else:
                by_parts.setdefault(len(s.box_parts[0]), []).append(i)
        phi, grad = np.zeros(pos.shape[:2]), np.zeros(pos.shape)
        for rows in by_parts.values():  # one batch whatever their sizes (pipeline.distance.field.boxes_query_links)
            poses = np.stack([_object_pose(self.slots[i], self.slots[i].objects[0]) for i in rows])
            half, centre = (np.stack([self.slots[i].box_parts[k] for i in rows]) for k in (0, 1))
            phi[rows], grad[rows] = boxes_query_links(pos[rows], poses, half, centre)
        for rows in groups.values():
            slot = self.slots[rows[0]]
            poses = np.stack([np.stack([_object_pose(self.slots[i], o) for o in slot.objects]) for i in rows])
            near = slot.fields.query_links(pos[rows], poses)
            phi[rows], grad[rows] = near.phi, near.grad
        command = root_command_to(qpos, target_q, target_v)
        if self.cfg.contract == "lessmimic_demo":
            task = np.array([TASK_CONDITION.get(s.episode.task, 0.0) for s in self.slots])
            df, command = demo_features(phi, grad, rot).reshape(n, -1), demo_command(command, task)
        else:
            df = interaction_features(phi, grad, vel).reshape(n, -1)
        return Obs(proprioception(qpos, qvel, last), command, df)

    def meters(self) -> list[TaskMeter]:
        return [s.meter for s in self.slots]

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()


def _object_pose(slot: EnvSlot, o) -> np.ndarray:
    adr = slot.scene.object_qpos_adr.get(o.name)
    return slot.data.qpos[adr : adr + 7].copy() if adr is not None else o.pose[0]
