"""What a reference asks that the G1 cannot do, decided before tracking, from physics alone: the rejection
classes, each proven on the reference with its figure (:func:`rejection`, :func:`rejection_reason`).

**out of reach**: the clip labels a hand in contact, and the whole-body reference leaves it farther than
:data:`UNREACHED_M` from the object's surface (the retargeter's contact task and the feasible re-solve could not
close the gap within the G1's limits: an overhead lift, an object beyond the arms) on more than :data:`REJECT_FRAC`
of the labelled hand-frames and for at least :data:`REJECT_MIN_S` (:func:`reach_figures`; the figure: the median
gap).

**over torque**: holding the reference still needs more than a motor gives, ``|tau_s| / tau_max > 1`` for some
upper-body joint (:mod:`physicalize.static_torque`, with the grasp's planned hand loads) for at least
:data:`REJECT_MIN_S` (the figure: the joint and the ratio).

**needs a grip** (:func:`hold_feasibility`). The G1's hands in our model are capsules: a hand can push on an object
and rub along it (friction), never pull or grip. At every frame a hand holds an object in the reference
(:class:`physicalize.grasp.GraspSchedule`), the object's motion needs the net external force
``F = m (a + g e_z)`` (its reference track's acceleration ``a``; ``m`` its mass). The hands can give any
non-negative combination of their friction cones' edges (inward normal ``n_k``, hand-object friction ``mu``:
``n_k + mu t``, ``t`` in 8 directions of the tangent plane); the floor adds, while the object rests on it (its
lowest point within :data:`RESTING_M` of the floor), its support: the whole cone about ``e_z`` (object-floor
friction ``mu_f``) while the object stands still, and only ``e_z - mu_f v/|v|`` while it slides at ``v`` (kinetic
friction opposes the motion: the floor cannot help push). ``F`` is producible iff it lies in the cone those
vectors span: non-negative least squares, ``min ||V w - F||, w >= 0``, with a residual within
:data:`FORCE_TOL` of ``|F|`` (plus :data:`FORCE_TOL_N`). A reference whose held frames need a force outside that
cone on more than :data:`REJECT_FRAC` of them (and for at least :data:`REJECT_MIN_S`) needs a grip: the human
lifts the object from one side against gravity, or raises a table by its near edge. Two kinds of take are never
``needs a grip``, whatever the G1's retargeted hands do (a hold the retargeting turned into one pressing hands
cannot keep is the retargeting's failure, tracked and reported as such, not the take's):

* a **slide** or a **small move** (:func:`pipeline.take.take_kind`): the floor carries the object and the hands
  push it, as in the Push task, or barely move it. These two kinds are never rejected, by any class: what they ask
  of the hands and motors is the grasp plan's, not the take's, and a plan that asks too much fails in the
  simulation with its class;
* a **squeeze**: the human's wrists on opposite faces, ``n_l . n_r`` < :data:`SQUEEZE_OPPOSITION` over the
  frames both hands hold (``provenance["human_hand_opposition"]``, :func:`pipeline.take.human_hold`;
  for a G1 motion with no human, the reference grasp's own normals): two opposed hands' normal forces cancel and
  their friction carries the weight.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.optimize import nnls

from physicalize.grasp import GraspSchedule, hand_labels
from physicalize.grasp_config import GraspConfig
from physicalize.grasp_force import cone_edges, floor_friction
from physicalize.hand_reach import ObjectTracks, hand_reach
from pipeline.take import SLIDE, SMALL_MOVE, mean_opposition

GRAVITY = 9.81
RESTING_M = 0.01  # an object whose lowest point is this close to the floor rests on it
SLIDING_MPS = 0.05  # an object resting and moving faster than this slides (kinetic floor friction)
FORCE_TOL = 0.1  # a force is producible when the cone's nearest force is within this share of it ...
FORCE_TOL_N = 1.0  # ... plus this [N]
REJECT_FRAC = 0.5  # of the held frames, beyond which a reference is rejected ...
REJECT_MIN_S = 0.5  # ... when they also last this long (a brief touch is no hold)
UNREACHED_M = GraspConfig().max_gap  # a labelled hand farther than this from the object cannot hold it
GAP_SEARCH_M = 1.0  # distances are searched up to this (farther counts as this)
SQUEEZE_OPPOSITION = -0.5  # n_l . n_r below this over the two-handed frames: a squeeze
OUT_OF_REACH, OVER_TORQUE, NEEDS_A_GRIP = "out of reach", "over torque", "needs a grip"
NEVER_REJECTED = (SLIDE, SMALL_MOVE)  # the floor carries the object: the hands push it or barely move it


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


def reach_figures(scene, ref, contact_links: tuple[str, ...], contacts: np.ndarray | None, objects: dict) -> dict:
    """``reference_hand_unreached_frac`` (of the hand-frames the clip labels in contact, the share where the
    reference hand is farther than :data:`UNREACHED_M` from its nearest object), ``reference_hand_unreached_s``
    (the frames with such a hand, in seconds) and ``reference_hand_gap_m`` (their median distance; None: none)."""
    labels = hand_labels(contact_links, contacts, ref.frames, GraspConfig())
    out = {"reference_hand_unreached_frac": 0.0, "reference_hand_unreached_s": 0.0, "reference_hand_gap_m": None}
    if not labels.any() or not scene.object_qpos_adr:
        return out
    dist = np.minimum(hand_reach(scene, ref, ObjectTracks.of(scene, objects), GAP_SEARCH_M).dist, GAP_SEARCH_M)
    far = labels & (dist > UNREACHED_M)
    out["reference_hand_unreached_frac"] = float(far.sum() / labels.sum())
    out["reference_hand_unreached_s"] = float(far.any(axis=1).sum() / ref.fps)
    out["reference_hand_gap_m"] = float(np.median(dist[far])) if far.any() else None
    return out


def grasp_opposition(grasp: GraspSchedule | None) -> float | None:
    """Mean ``n_l . n_r`` of the reference grasp's inward normals over the frames both hands hold (None: none)."""
    if grasp is None or not grasp.grasped.all(axis=1).any():
        return None
    return mean_opposition(grasp.normal[grasp.grasped.all(axis=1)])


def is_squeeze(figures: dict) -> bool:
    """Both wrists on opposite faces (module docstring): the human's opposition, else the reference grasp's."""
    opp = figures.get("human_hand_opposition")
    opp = figures.get("reference_hand_opposition") if opp is None else opp
    return opp is not None and opp < SQUEEZE_OPPOSITION


def rejection(figures: dict) -> str | None:
    """The class a reference is rejected for (None: tracked), in this order: ``out of reach``, ``over torque``,
    ``needs a grip`` (module docstring); a slide or a small move never."""
    if figures.get("take_kind") in NEVER_REJECTED:
        return None
    if (
        figures.get("reference_hand_unreached_frac", 0.0) > REJECT_FRAC
        and figures.get("reference_hand_unreached_s", 0.0) >= REJECT_MIN_S
    ):
        return OUT_OF_REACH
    if figures.get("reference_static_torque_over_s", 0.0) >= REJECT_MIN_S:
        return OVER_TORQUE
    if is_squeeze(figures):
        return None
    if (
        figures.get("reference_hold_infeasible_frac", 0.0) > REJECT_FRAC
        and figures.get("reference_hold_infeasible_s", 0.0) >= REJECT_MIN_S
    ):
        return NEEDS_A_GRIP
    return None


def rejection_reason(figures: dict, rejected: str) -> str:
    """One line: the class and the figure that proves it."""
    f = figures
    if rejected == OUT_OF_REACH:
        why = (
            f"the hands labelled in contact stay {f['reference_hand_gap_m']:.2f} m (median) from the object on "
            f"{f['reference_hand_unreached_frac']:.0%} of their labelled frames "
            f"({f['reference_hand_unreached_s']:.2f} s)"
        )
    elif rejected == OVER_TORQUE:
        why = (
            f"holding the reference still needs {f['reference_static_torque_ratio_max']:.2f} x the effort limit of "
            f"{f['reference_static_torque_joint']} (at t={f['reference_static_torque_at_s']:.2f} s; above 1 for "
            f"{f['reference_static_torque_over_s']:.2f} s)"
        )
    else:
        why = (
            f"pressing hands cannot give the force the held object needs on {f['reference_hold_infeasible_frac']:.0%} "
            f"of the held frames, from t={f['reference_hold_infeasible_from_s']:.2f} s (it must be pulled or gripped)"
        )
    return f"rejected: {rejected}: {why}"
