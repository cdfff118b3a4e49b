"""Closed-loop tracking of a reference in MuJoCo, recorded as state-action data, and its open-loop replay.

Control at 50 Hz over 200 Hz physics: at control frame ``t`` the recorded state is the
simulation's ``(qpos, qvel)`` (robot and objects), the controller picks the joint targets
``action[t]``, which the position actuators hold for :data:`SUBSTEPS` physics steps. Also recorded
per frame: the actuator torques (mean over the hold), the feet's vertical contact forces, the
robot-object contact flags per link, and any external force (``xfrc_applied``, only ever set by
a test's ``perturb`` callback: the teacher never assists the root or the object).

MuJoCo on the CPU is deterministic, so :func:`replay` of the recorded actions from the recorded
initial state in a fresh ``MjData`` reproduces the recorded states (the self-consistency check).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from physicalize.reference import Reference
from physicalize.stepping import foot_floor_forces
from physicalize.wbc import WholeBodyController
from pipeline.contacts import ContactSets, robot_contacts
from pipeline.robot import NQ_ROBOT, NUM_JOINTS, NV_ROBOT
from pipeline.scene import Scene, link_collision_geoms
from pipeline.terms.fall import fallen
from pipeline.terms.layout import SUBSTEPS


@dataclass
class Rollout:
    """Recorded closed-loop trajectory (``T`` control frames; ``T`` <= the reference's when fallen)."""

    qpos: np.ndarray  # (T, model.nq): robot then objects
    qvel: np.ndarray  # (T, model.nv)
    action: np.ndarray  # (T, 29) joint position targets held from frame t to t+1
    torque: np.ndarray  # (T, 29) actuator torques, mean over the hold
    foot_force: np.ndarray  # (T, 2) vertical contact force on each foot from the floor [N]
    contact: np.ndarray  # (T, len(contact_links)) link touches an object
    penetration: np.ndarray  # (T,) deepest contact penetration over the hold [m] (>= 0)
    external_force: np.ndarray  # (T,) largest |xfrc_applied| over the hold [N]
    qp_failures: int
    fell_at: int | None
    seconds: float
    final_qpos: np.ndarray  # state after the last action (for the replay check)
    final_qvel: np.ndarray
    support: np.ndarray | None = None  # (T, 2) bool: the feet the controller held in support (after stepping)
    landing_shift: np.ndarray | None = None  # (T, 2, 2): each foot's capture-point landing shift [m]

    @property
    def frames(self) -> int:
        return self.qpos.shape[0]


def initial_state(
    scene: Scene, ref: Reference, objects: dict[str, np.ndarray], frame: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """``(qpos, qvel)`` at reference frame ``frame`` (default the first): the reference pose, its velocity
    (the median over frames ``frame..frame+4``: a retargeted clip's first frame is solved on its own and
    its finite difference can jump), objects at their pose, at rest."""
    m = scene.model
    qpos, qvel = np.zeros(m.nq), np.zeros(m.nv)
    qpos[:NQ_ROBOT], qvel[:NV_ROBOT] = ref.qpos[frame], np.median(ref.qvel[frame : frame + 5], axis=0)
    for name, adr in scene.object_qpos_adr.items():
        qpos[adr : adr + 7] = objects[name][frame]
    return qpos, qvel


def _link_contacts(m, d, link_geoms: list[set[int]], object_geoms: set[int]) -> np.ndarray:
    """(len(link_geoms),) bool: each link (its geoms) touches an object (one of ``object_geoms``)."""
    out = np.zeros(len(link_geoms), bool)
    for c in robot_contacts(m, d, set().union(*link_geoms)):
        if c.other in object_geoms:
            for k, g in enumerate(link_geoms):
                if c.geom in g:
                    out[k] = True
    return out


RECORDED = (
    "qpos",
    "qvel",
    "action",
    "torque",
    "foot_force",
    "contact",
    "penetration",
    "external_force",
    "support",
    "landing_shift",
)


@dataclass(frozen=True)
class Snapshot:
    """A :class:`Tracker` at one control frame: MuJoCo's integration state (``mjSTATE_INTEGRATION``: restores
    ``MjData`` exactly), the controller's own state, and how much had been recorded."""

    t: int
    physics: np.ndarray
    controller: tuple
    recorded: int
    fails: int
    fell_at: int | None


class Tracker:
    """Closed-loop tracking of a reference advanced one control frame at a time (:func:`simulate` runs it to the
    end), whose state can be saved and restored exactly (:meth:`snapshot`, :meth:`restore`) and whose reference can be
    swapped between frames (:attr:`ref`): the search (:mod:`physicalize.search`) tries several continuations from
    one state. A restored tracker continues bit for bit as the original did from that frame."""

    def __init__(
        self,
        scene: Scene,
        ref: Reference,
        controller: WholeBodyController,
        qpos0: np.ndarray,
        qvel0: np.ndarray,
        *,
        contact_links: tuple[str, ...] = (),
        perturb: Callable[[int, mujoco.MjData], None] | None = None,
        residual: Callable[[mujoco.MjData, Reference, int, np.ndarray], np.ndarray] | None = None,
    ):
        m = self.model = scene.model
        self.ref, self.controller, self.perturb, self.residual = ref, controller, perturb, residual
        self.data = mujoco.MjData(m)
        self.data.qpos[:], self.data.qvel[:] = qpos0, qvel0
        self.robot, self.torso = ContactSets.of(m), m.body("torso_link").id
        self.link_geoms = [set(link_collision_geoms(m, b)) for b in contact_links]
        self.object_geoms = {g for g in range(m.ngeom) if m.geom_bodyid[g] in set(scene.object_body_id.values())}
        self.rec: dict[str, list] = {k: [] for k in RECORDED}
        self.t, self.fails, self.fell_at = 0, 0, None
        self.steps = 0  # control frames simulated, restores or not: what a search's budget counts
        self.started = time.perf_counter()

    def step(self) -> None:
        """Record frame ``t``, hold the controller's joint targets for :data:`SUBSTEPS` physics steps, test the fall."""
        m, d, ref, rec, t = self.model, self.data, self.ref, self.rec, self.t
        T = ref.frames
        mujoco.mj_forward(m, d)
        rec["qpos"].append(d.qpos.copy())
        rec["qvel"].append(d.qvel.copy())
        rec["foot_force"].append(foot_floor_forces(self.robot, d))
        rec["contact"].append(_link_contacts(m, d, self.link_geoms, self.object_geoms))
        sol = self.controller.solve(d, ref.target(t))
        self.fails += not sol.ok
        rec["support"].append(sol.stance if sol.stance is not None else ref.stance[min(t, T - 1)])
        rec["landing_shift"].append(sol.landing_shift if sol.landing_shift is not None else np.zeros((2, 2)))
        action = sol.action if self.residual is None else self.residual(d, ref, t, sol.action)
        d.ctrl[:] = action
        tau, pen, ext = np.zeros(NUM_JOINTS), 0.0, 0.0
        for _ in range(SUBSTEPS):
            if self.perturb is not None:
                self.perturb(t, d)
            ext = max(ext, float(np.abs(d.xfrc_applied).max()))
            mujoco.mj_step(m, d)
            tau += d.actuator_force / SUBSTEPS
            if d.ncon:
                pen = max(pen, float(-d.contact.dist[: d.ncon].min()))
        rec["action"].append(action)
        rec["torque"].append(tau)
        rec["penetration"].append(max(pen, 0.0))
        rec["external_force"].append(ext)
        k = min(t + 1, T - 1)
        if self.fell_at is None and fallen(d, ref.qpos[k, 2], self.torso, ref.torso_quat[k]):
            self.fell_at = t + 1
        self.t, self.steps = t + 1, self.steps + 1

    def run(self, until: int, stop_on_fall: bool = True) -> None:
        """Step until frame ``until`` (at most the reference's end), or the fall."""
        while self.t < min(until, self.ref.frames) and not (stop_on_fall and self.fell_at is not None):
            self.step()

    def snapshot(self) -> Snapshot:
        state = np.zeros(mujoco.mj_stateSize(self.model, mujoco.mjtState.mjSTATE_INTEGRATION))
        mujoco.mj_getState(self.model, self.data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        return Snapshot(self.t, state, self.controller.state(), len(self.rec["qpos"]), self.fails, self.fell_at)

    def restore(self, snap: Snapshot) -> None:
        """Back to ``snap``, this tracker's or a copy's (a search's worker, :mod:`physicalize.search.children`): the
        frames recorded from its frame on are dropped; those before it that this tracker never recorded are None
        (what a restored tracker's readers read is what it records after the restore)."""
        mujoco.mj_setState(self.model, self.data, snap.physics, mujoco.mjtState.mjSTATE_INTEGRATION)
        self.controller.set_state(snap.controller)
        for v in self.rec.values():
            del v[snap.recorded :]
            v.extend([None] * (snap.recorded - len(v)))
        self.t, self.fails, self.fell_at = snap.t, snap.fails, snap.fell_at

    def rollout(self) -> Rollout:
        """What was recorded, as a :class:`Rollout`."""
        return Rollout(
            **{k: np.asarray(v) for k, v in self.rec.items()},
            qp_failures=self.fails,
            fell_at=self.fell_at,
            seconds=time.perf_counter() - self.started,
            final_qpos=self.data.qpos.copy(),
            final_qvel=self.data.qvel.copy(),
        )


def simulate(
    scene: Scene,
    ref: Reference,
    controller: WholeBodyController,
    qpos0: np.ndarray,
    qvel0: np.ndarray,
    *,
    contact_links: tuple[str, ...] = (),
    perturb: Callable[[int, mujoco.MjData], None] | None = None,
    stop_on_fall: bool = True,
    residual: Callable[[mujoco.MjData, Reference, int, np.ndarray], np.ndarray] | None = None,
) -> Rollout:
    """Track ``ref`` from ``(qpos0, qvel0)``; ``perturb(t, data)`` may set ``xfrc_applied`` (tests only).
    With a ``residual(data, ref, t, base_action)`` (:class:`physicalize.residual.ResidualPolicy`) the
    applied (and recorded) targets are its output, else the controller's."""
    tracker = Tracker(
        scene, ref, controller, qpos0, qvel0, contact_links=contact_links, perturb=perturb, residual=residual
    )
    tracker.run(ref.frames, stop_on_fall)
    return tracker.rollout()


def replay(
    model: mujoco.MjModel, qpos0: np.ndarray, qvel0: np.ndarray, actions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop replay in a fresh ``MjData``: ``(qpos (T+1, nq), qvel (T+1, nv))`` after each held action."""
    d = mujoco.MjData(model)
    d.qpos[:], d.qvel[:] = qpos0, qvel0
    qs, vs = [d.qpos.copy()], [d.qvel.copy()]
    for a in actions:
        d.ctrl[:] = a
        for _ in range(SUBSTEPS):
            mujoco.mj_step(model, d)
        qs.append(d.qpos.copy())
        vs.append(d.qvel.copy())
    return np.asarray(qs), np.asarray(vs)
