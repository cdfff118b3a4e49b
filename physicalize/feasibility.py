"""What a reference asks that the G1 cannot do, decided before tracking, from physics alone.

**Hands that only press** (:func:`hold_feasibility`). The G1's hands in our model are capsules: a hand can push
on an object and rub along it (friction), never pull or grip. At every frame a hand holds an object in the
reference (:class:`physicalize.grasp.GraspSchedule`), the object's motion needs the net external force
``F = m (a + g e_z)`` (its reference track's acceleration ``a``; ``m`` its mass). The hands can give any
non-negative combination of their friction cones' edges (inward normal ``n_k``, hand-object friction ``mu``:
``n_k + mu t``, ``t`` in 8 directions of the tangent plane); the floor adds, while the object rests on it (its
lowest point within :data:`RESTING_M` of the floor), its support: the whole cone about ``e_z`` (object-floor
friction ``mu_f``) while the object stands still, and only ``e_z - mu_f v/|v|`` while it slides at ``v`` (kinetic
friction opposes the motion: the floor cannot help push). ``F`` is producible iff it lies in the cone those
vectors span: non-negative least squares, ``min ||V w - F||, w >= 0``, with a residual within
:data:`FORCE_TOL` of ``|F|`` (plus :data:`FORCE_TOL_N`). Torques are not checked (a lenient test).

A reference whose held frames need a force outside that cone on more than :data:`REJECT_FRAC` of them (and for
at least :data:`REJECT_MIN_S`) is rejected ``needs a grip``: the human pulls the object by an edge, or holds it
from one side against gravity, which a pressing hand cannot. Squeezing is inside the cone (two opposed hands'
normal forces cancel and their friction carries the weight: a two-handed box lift is feasible), so is pushing an
object along the floor from behind, and pressing on its top while the floor carries it.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.optimize import nnls

from physicalize.grasp import GraspSchedule
from physicalize.grasp_force import floor_friction

GRAVITY = 9.81
RESTING_M = 0.01  # an object whose lowest point is this close to the floor rests on it
SLIDING_MPS = 0.05  # an object resting and moving faster than this slides (kinetic floor friction)
FORCE_TOL = 0.1  # a force is producible when the cone's nearest force is within this share of it ...
FORCE_TOL_N = 1.0  # ... plus this [N]
REJECT_FRAC = 0.5  # of the held frames, beyond which a reference is rejected ...
REJECT_MIN_S = 0.5  # ... when they also last this long (a brief touch is no hold)
DIRECTIONS = 8  # tangent directions of a friction cone's edges


def cone_edges(n: np.ndarray, mu: float, k: int = DIRECTIONS) -> np.ndarray:
    """(k, 3) edges of the friction cone about the unit normal ``n`` (inscribed polygon): ``n + mu t_i``."""
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    ang = 2 * np.pi * np.arange(k) / k
    return n[None] + mu * (np.cos(ang)[:, None] * t1[None] + np.sin(ang)[:, None] * t2[None])


def producible(force: np.ndarray, edges: np.ndarray) -> bool:
    """Whether ``force`` (3,) lies in the cone spanned by the rows of ``edges`` (within the tolerances)."""
    if not len(edges):
        return float(np.linalg.norm(force)) <= FORCE_TOL_N
    _, residual = nnls(edges.T, force)
    return residual <= FORCE_TOL * float(np.linalg.norm(force)) + FORCE_TOL_N


def _lowest_height(model: mujoco.MjModel, data: mujoco.MjData, geoms: list[int], floor: int) -> float:
    out = np.inf
    fromto = np.zeros(6)
    for g in geoms:
        out = min(out, mujoco.mj_geomDistance(model, data, g, floor, 1.0, fromto))
    return float(out)


def grasp_feasibility(model: mujoco.MjModel, grasp: GraspSchedule | None, object_qpos: np.ndarray, fps: float) -> dict:
    """:func:`hold_feasibility` of a grasp schedule's holds (no grasp: nothing held)."""
    if grasp is None:
        return hold_feasibility(
            model, np.zeros((0, 2), bool), np.zeros((0, 2), int), np.zeros((0, 2, 3)), 0.0, object_qpos, fps
        )
    return hold_feasibility(model, grasp.grasped, grasp.body, grasp.normal, grasp.mu, object_qpos, fps)


def hold_feasibility(
    model: mujoco.MjModel,
    grasped: np.ndarray,
    body: np.ndarray,
    normal: np.ndarray,
    mu: float,
    object_qpos: np.ndarray,
    fps: float,
) -> dict:
    """Figures of the reference's holds (module docstring): ``reference_hold_frames``, the frames some hand holds
    an object, and ``reference_hold_infeasible_frac`` (``_s``), the share (the seconds) of them whose needed force
    no pressing hands (and floor) can give, with ``reference_hold_infeasible_from_s``, when that first happens
    (None: never). Per frame and hand (left, right): ``grasped`` (T, 2), the ``body`` id held (T, 2) and the
    inward surface ``normal`` (T, 2, 3) at the hand, hand-object friction ``mu``; ``object_qpos`` (T, nq - 36):
    the scene's free objects per frame along their reference tracks."""
    out = {
        "reference_hold_frames": 0,
        "reference_hold_infeasible_s": 0.0,
        "reference_hold_infeasible_frac": 0.0,
        "reference_hold_infeasible_from_s": None,
    }
    if not grasped.any():
        return out
    T = min(len(grasped), len(object_qpos))
    data = mujoco.MjData(model)
    floor = model.geom("floor").id
    dt = 1.0 / fps
    held_frames, bad = 0, []
    for b in sorted(set(body[grasped].tolist())):
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == b and model.geom_contype[g]]
        adr = model.jnt_qposadr[model.body_jntadr[b]] - (model.nq - object_qpos.shape[1])
        pos = object_qpos[:T, adr : adr + 3]
        vel = np.gradient(pos, dt, axis=0) if T > 1 else np.zeros_like(pos)
        acc = np.gradient(vel, dt, axis=0) if T > 2 else np.zeros_like(pos)
        mass, mu_f = float(model.body_subtreemass[b]), floor_friction(model, geoms)
        for t in np.flatnonzero((body[:T] == b).any(axis=1)):
            hands = [k for k in range(2) if grasped[t, k] and body[t, k] == b]
            if not hands:
                continue
            held_frames += 1
            edges = [cone_edges(normal[t, k] / np.linalg.norm(normal[t, k]), mu) for k in hands]
            data.qpos[-object_qpos.shape[1] :] = object_qpos[t]
            mujoco.mj_kinematics(model, data)
            if _lowest_height(model, data, geoms, floor) < RESTING_M:
                speed = float(np.linalg.norm(vel[t, :2]))
                up = np.array([0.0, 0.0, 1.0])
                if speed > SLIDING_MPS:
                    edges.append((up - mu_f * np.r_[vel[t, :2] / speed, 0.0])[None])
                else:
                    edges.append(cone_edges(up, mu_f))
            need = mass * (acc[t] + np.array([0.0, 0.0, GRAVITY]))
            if not producible(need, np.vstack(edges)):
                bad.append(t)
    out["reference_hold_frames"] = held_frames
    out["reference_hold_infeasible_s"] = len(bad) / fps
    out["reference_hold_infeasible_frac"] = len(bad) / max(held_frames, 1)
    out["reference_hold_infeasible_from_s"] = min(bad) / fps if bad else None
    return out


def rejection(figures: dict) -> str | None:
    """The class a reference is rejected for (None: tracked): ``needs a grip`` (module docstring)."""
    if (
        figures.get("reference_hold_infeasible_frac", 0.0) > REJECT_FRAC
        and figures.get("reference_hold_infeasible_s", 0.0) >= REJECT_MIN_S
    ):
        return "needs a grip"
    return None
