"""Physicalize one retargeted clip: track its reference (:mod:`physicalize.problem`) closed loop in MuJoCo
with the teacher (``base``: :class:`physicalize.wbc.WholeBodyController`, optionally plus a learned residual,
:mod:`physicalize.residual`), record the state-action trajectory (:mod:`physicalize.rollout`), replay the
actions open loop to check self-consistency, and measure the validity figures (:mod:`physicalize.validate`).
The base teacher tries its QP gain sets (:data:`physicalize.wbc_config.TEACHER_GAINS`) in order until a rollout
is valid."""

from __future__ import annotations

import hashlib
import math
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

from physicalize.balance import balance_figures, com_series, reference_balance_figures
from physicalize.feasibility import (
    grasp_feasibility,
    grasp_opposition,
    reach_figures,
    rejection,
    rejection_reason,
)
from physicalize.guidance import ObjectGuidance
from physicalize.object_trace import object_trace_figures
from physicalize.payload import capped, held_objects, load_scale
from physicalize.problem import object_qpos, tracking_problem
from physicalize.rollout import Rollout, initial_state, replay, simulate
from physicalize.search import beam
from physicalize.search.beam import SearchConfig
from physicalize.start import clean_start, prefix_frames
from physicalize.static_torque import static_torque_figures
from physicalize.validate import failure_class, validate
from physicalize.wbc import WholeBodyController
from physicalize.wbc_config import TEACHER_GAINS, WBCConfig
from pipeline.clip import RobotClip
from pipeline.errors import InputError
from pipeline.geometry import provenance_variant
from pipeline.robot import FREE_NQ, NQ_ROBOT
from pipeline.take import take_kind

TEACHERS = ("base", "base+residual:<checkpoint>", "kinematic")
REPLAY_TOL_M = 1e-6


@dataclass(frozen=True)
class TeacherSpec:
    """A parsed ``--teacher``: the base QP controller, optionally with a learned residual checkpoint
    (``digest``: the checkpoint file's sha256, part of the cache key and the provenance)."""

    name: str
    checkpoint: Path | None = None
    digest: str | None = None


def parse_teacher(teacher: str) -> TeacherSpec:
    """``base``, ``base+residual:<checkpoint path>`` or ``kinematic`` (no physics: :mod:`physicalize.kinematic`);
    anything else, or a checkpoint that is not a file, is an :class:`InputError` (one line naming the teacher or
    the path)."""
    if teacher in ("base", "kinematic"):
        return TeacherSpec(teacher)
    prefix = "base+residual:"
    if not teacher.startswith(prefix) or not teacher[len(prefix) :]:
        raise InputError(teacher, "--teacher", f"unknown teacher; available: {', '.join(TEACHERS)}")
    path = Path(teacher[len(prefix) :]).expanduser()
    if not path.is_file():
        raise InputError(
            path, "--teacher", "residual checkpoint not found (train one with `lessmimic physicalize-residual`)"
        )
    return TeacherSpec("base+residual", path, hashlib.sha256(path.read_bytes()).hexdigest())


_RESIDUALS: dict = {}


def load_residual(path: str, digest: str):
    """The checkpoint's policy, loaded once per (path, content)."""
    if (path, digest) not in _RESIDUALS:
        from physicalize.residual import ResidualPolicy

        _RESIDUALS[(path, digest)] = ResidualPolicy.load(path)
    return _RESIDUALS[(path, digest)]


def robot_alone(clip: RobotClip) -> RobotClip:
    """The clip's body motion with no object: no object track, no robot-object contact label (hands free, the
    reference otherwise the same), marked ``provenance["robot_alone"]``. Whether a take's walk holds on its own
    is measured on this (``bench/bench_physicalize_real.py --robot-only``), to the same bars less the object's."""
    return replace(
        clip, objects=(), contact_links=(), contacts=None, provenance={**clip.provenance, "robot_alone": True}
    )


def first_contact_s(clip: RobotClip) -> float | None:
    """When the clip's robot first touches an object (any contact link or object contact flag), None if never."""
    flags = [o.contact for o in clip.objects if o.contact is not None]
    if clip.contacts is not None and clip.contacts.size:
        flags.append(clip.contacts.any(axis=1))
    touching = np.flatnonzero(np.any(flags, axis=0)) if flags else np.zeros(0, int)
    return float(touching[0] / clip.fps) if touching.size else None


def _reference_figures(scene, ref, clip: RobotClip) -> tuple[dict, str]:
    """What the tracked reference asks beyond the robot, the same for every rollout of it: the static
    upper-body torque (:mod:`physicalize.static_torque`), the share of held frames whose planned hand
    forces leave the friction cones, and whether pressing hands can give the force the held objects need
    (:mod:`physicalize.feasibility`); with the cause an invalid rollout's reason names ("" when none); and
    when the reference first touches an object (``reference_first_contact_s``, for the failure class)."""
    fps = clip.fps
    loads = None if ref.grasp is None else (ref.grasp.offset, ref.grasp.force)
    # what the reference asks of the upper body
    figures = static_torque_figures(ref.qpos, loads, scene.profile.effort_limit, fps)
    figures["reference_first_contact_s"] = first_contact_s(clip)
    figures.update(grasp_feasibility(scene.model, ref.grasp, object_qpos(scene, clip, ref.frames), fps))
    figures.update(reach_figures(scene, ref, clip.contact_links, clip.contacts, {o.name: o.pose for o in clip.objects}))
    kind = take_kind(clip.objects[0].pose) if clip.objects else None
    figures["take_kind"] = None if kind is None else kind.kind
    figures["take_rise_m"], figures["take_travel_m"] = (None, None) if kind is None else (kind.rise_m, kind.travel_m)
    figures["human_hand_opposition"] = clip.provenance.get("human_hand_opposition")
    figures["reference_hand_opposition"] = grasp_opposition(ref.grasp)
    if ref.grasp is None:
        held = outside = np.zeros(0, bool)
    else:
        held = ref.grasp.grasped.any(axis=1)
        outside = held & ~ref.grasp.friction_ok
    figures["reference_grasp_outside_friction_frac"] = float(outside.sum() / max(held.sum(), 1))  # of the held frames
    return figures, _hold_cause(figures, outside, fps)


def _hold_cause(figures: dict, outside: np.ndarray, fps: float) -> str:
    """What an invalid rollout's reason adds about the reference's holds: where no pressing hands (and floor) can
    give the force the held object needs (:func:`physicalize.feasibility.hold_feasibility`: physics, a cause no
    controller overcomes); else where only the grasp plan's share of it per hand leaves the friction cones (the hands
    together could give it: ``sub8_largebox_000``'s plan left the cones on 11% of its held frames, the physics on 6%).
    """
    start = figures.get("reference_hold_infeasible_from_s")
    if start is not None:
        share = figures["reference_hold_infeasible_frac"]
        return (
            f"; pressing hands cannot give the force the held object needs on {share:.0%} of the held frames from "
            f"t={start:.2f} s"
        )
    if outside.any():
        return (
            "; the grasp plan's force per hand leaves its friction cone from "
            f"t={np.flatnonzero(outside)[0] / fps:.2f} s (the hands together could give it)"
        )
    return ""


def _payload_capped(clip: RobotClip, scene, ref) -> tuple[RobotClip, dict] | None:
    """``clip`` with its held objects as heavy as the upper body can hold in the reference's poses, and the
    ``payload_capped`` figure (:mod:`physicalize.payload`); None when the clip is not a geometry variant (its
    object's mass is the world's), nothing is held or the poses alone are over."""
    if provenance_variant(clip.provenance) in (None, "x1"):
        return None
    if ref.grasp is None or not (held := held_objects(ref.grasp.obj)):
        return None
    k = load_scale(ref.qpos, (ref.grasp.offset, ref.grasp.force), scene.profile.effort_limit)
    return capped(clip, held, k) if 0.0 < k < 1.0 else None


def _figures(
    scene, roll: Rollout, clip: RobotClip, objects, qpos0, qvel0, perturb, reference: tuple[dict, str]
) -> dict:
    """The validity figures of one rollout (:mod:`physicalize.validate`), its reference's figures
    (:func:`_reference_figures`) and the open-loop replay check."""
    figures = validate(scene, roll, clip.qpos, objects)
    figures.update(reference[0])
    if not figures["valid"]:
        figures["reason"] += reference[1]
    qs, _ = replay(scene.model, qpos0, qvel0, roll.action)
    figures["replay_err_max_m"] = float(np.abs(np.vstack([qs[:-1] - roll.qpos, qs[-1:] - roll.final_qpos])).max())
    if figures["replay_err_max_m"] > REPLAY_TOL_M and perturb is None:
        figures["valid"] = False
        figures["reason"] = "; ".join(
            filter(None, [figures["reason"], f"replay error {figures['replay_err_max_m']:.3g} m > {REPLAY_TOL_M:g}"])
        )
    figures["failure"] = failure_class(figures)
    return figures


def _traces(scene, ref, roll: Rollout, touch_force: float, clip: RobotClip, objects) -> dict:
    """What a rollout's failure is traced by: where it lost its balance (:mod:`physicalize.balance`) and where it
    lost its object (:mod:`physicalize.object_trace`)."""
    figures = balance_figures(scene.model, ref, roll, touch_force)
    figures.update(object_trace_figures(ref, roll, scene.object_qpos_adr, objects, clip.contact_links))
    return figures


def _search(
    scene, ref, clip, objects, state0, ref_figures, tried, gains, config: SearchConfig, workers=1, perturb=None
):
    """``(gain set, rollout, figures)`` of the search (:mod:`physicalize.search.beam`) from the gain set whose rollout
    fell last: up to ``config.attempts`` searches (seeds ``config.seed``, ``+ 1``, ...) sharing the budget
    (:attr:`~physicalize.search.beam.SearchConfig.children_per_s`) until one's rollout is valid, else the one that
    went wrong last (:func:`_how_far`; the earlier on a tie: a later attempt has less budget left: on
    ``sub2_woodchair_002`` at 120 the third searched three segments and stood no longer than the teacher); its
    figures carry ``search``: where it started, its segments, the children and CPU-seconds of every attempt, and the
    verdict before and after (its CPU-seconds: of the ``workers`` processes its children ran in too); ``perturb``: every
    tracker's (the object guidance, :mod:`physicalize.guidance`). None when no tried rollout fell."""
    fell = [(k, r, f) for k, r, f in tried if r.fell_at is not None]
    if not fell:
        return None
    index, nominal, before = max(fell, key=lambda x: x[1].fell_at)
    make = partial(WholeBodyController, scene.model, scene.profile, gains[index])
    budget, spent, children, frames, remote = beam.frame_budget(config, ref.frames, clip.fps), 0.0, 0, 0, 0.0
    best = None
    for attempt in range(config.attempts):
        share, left = replace(config, seed=config.seed + attempt), budget - frames
        kw = {"contact_links": clip.contact_links, "objects": objects, "max_frames": left, "workers": workers}
        kw["perturb"] = perturb
        result = beam.search(scene, ref, make, *state0, nominal, share, **kw)
        spent, children, frames = spent + result.cpu_s, children + result.children, frames + result.frames
        remote += result.worker_cpu_s
        now = _figures(scene, result.rollout, clip, objects, *state0, perturb, ref_figures)
        if best is None or _how_far(now) > _how_far(best[1]):
            best = result, now
        if now["valid"] or frames >= budget:
            break
    found, figures = best
    figures.update(_traces(scene, ref, found.rollout, gains[index].touch_force, clip, objects))
    figures["search"] = {
        "gain_set": index,
        "start_s": found.start / clip.fps,
        "segments": [seg.as_dict(clip.fps) for seg in found.segments],
        "attempts": attempt + 1,
        "children": children,
        "frames": frames,
        "cpu_s": spent,
        "worker_cpu_s": remote,
        "failure_before": before["failure"],
        "failure_after": figures["failure"],
        "reason_after": figures["reason"],
    }
    return index, found.rollout, figures


def _how_far(figures: dict) -> tuple[bool, float]:
    """How far a rollout got, to order rollouts by (the larger the further): valid first, then when it first went
    wrong, in seconds: its fall or its object's loss, whichever came first; infinite for one that neither fell nor
    lost its object (what failed it then is a bar met or missed over the whole clip)."""
    times = [t for t in (figures.get("fell_at_s"), figures.get("object_lost_at_s")) if t is not None]
    return bool(figures["valid"]), min(times, default=math.inf)


def _rejected(figures: dict, rejected: str) -> dict:
    """The figures of a clip rejected before tracking (:func:`physicalize.feasibility.rejection`)."""
    why = rejection_reason(figures, rejected)
    return {**figures, "valid": False, "rejected": rejected, "failure": None, "reason": why}


def physicalize_clip(
    clip: RobotClip,
    *,
    profile: str = "mjlab",
    reference: str = "feasible",
    perturb=None,
    teacher: str = "base",
    grasp: bool = True,
    gains: tuple[WBCConfig, ...] | None = None,
    search: SearchConfig | None = SearchConfig(),
    search_workers: int = 1,
    guide: float = 0.0,
) -> tuple[RobotClip | None, Rollout | None, dict, dict]:
    """(simulated clip, rollout, validity figures, CoM series) of one retargeted clip tracking the
    ``reference`` (see :func:`physicalize.problem.tracking_problem`) with the ``teacher`` (see :func:`parse_teacher`).
    A reference that asks what the robot cannot do (:func:`physicalize.feasibility.rejection`) is not tracked:
    ``(None, None, figures with "rejected": <class>, {})``.

    The base teacher tries the QP gain sets ``gains`` (default :data:`physicalize.wbc_config.TEACHER_GAINS`) in
    order from the same initial state and keeps the first rollout that is valid, else the one that went wrong last
    (:func:`_how_far`; the earlier set's on a tie): rejection sampling over controller gains, each rollout
    validated on its own. Where none is valid the search (:func:`_search`) runs, and its best is kept when it is
    valid or went wrong later still: an invalid clip carries the figures, traces and class of the furthest any
    rollout got (the 12 shared real takes searched with their objects: the search's best on 11, 6 of them standing to
    the end and only losing the object). ``figures`` name the set
    kept (``teacher_gains``, its index) and how many ran (``teacher_attempts``); timings count them all. The
    object loop's sets run only on a clip whose hands hold something (else they are the open loop's sets again).
    A residual teacher runs the first set only (its policy was trained on it). ``search_workers``: the processes the
    search's children run in (:mod:`physicalize.search.children`; the same result for any number). ``guide`` > 0:
    every rollout, the search's included, with the objects held on their tracks by
    :class:`physicalize.guidance.ObjectGuidance` at that scale (a measurement: such a clip fails the external force
    bar, so it is never valid)."""
    if guide < 0:
        raise ValueError(f"object guidance scale must be >= 0, got {guide}")
    spec = parse_teacher(teacher)
    residual = None if spec.checkpoint is None else load_residual(str(spec.checkpoint), spec.digest)
    gains = (TEACHER_GAINS if gains is None else tuple(gains))[: 1 if residual is not None else None]
    t0, cpu0 = time.perf_counter(), time.process_time()
    clip = clean_start(clip)
    scene, ref, objects, zmp = tracking_problem(clip, profile, reference, grasp)
    qpos0, qvel0 = initial_state(scene, ref, objects)
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0  # planning + tracking (not the checks)
    ref_figures = _reference_figures(scene, ref, clip)
    if ref_figures[0]["reference_static_torque_ratio_max"] > 1.0 and (lighter := _payload_capped(clip, scene, ref)):
        clip, payload = lighter  # what the hands hold, as heavy as the motors can hold (physicalize.payload)
        scene, ref, objects, zmp = tracking_problem(clip, profile, reference, grasp)
        qpos0, qvel0 = initial_state(scene, ref, objects)
        ref_figures = _reference_figures(scene, ref, clip)
        ref_figures[0].update(payload)
    if (rejected := rejection(ref_figures[0])) is not None:
        return None, None, _rejected(ref_figures[0], rejected), {}
    ref_figures[0].update(reference_balance_figures(ref, zmp))  # the same for every rollout: once
    if guide > 0:
        perturb = ObjectGuidance.of(scene, objects, clip.fps, guide)
    holds = ref.grasp is not None and bool(ref.grasp.grasped.any())
    tried = []
    for index, config in enumerate(gains):
        if config.object_loop is not None and not holds:  # nothing held: the same controller as an open-loop set
            continue
        t0, cpu0 = time.perf_counter(), time.process_time()
        controller = WholeBodyController(scene.model, scene.profile, config)
        roll = simulate(
            scene, ref, controller, qpos0, qvel0, contact_links=clip.contact_links, perturb=perturb, residual=residual
        )
        wall, cpu = wall + time.perf_counter() - t0, cpu + time.process_time() - cpu0
        figures = _figures(scene, roll, clip, objects, qpos0, qvel0, perturb, ref_figures)
        figures.update(_traces(scene, ref, roll, config.touch_force, clip, objects))
        tried.append((index, roll, figures))
        if tried[-1][2]["valid"]:
            break
    kept, roll, figures = max(tried, key=lambda x: _how_far(x[2]))  # the first of equals
    if not figures["valid"] and len(tried) > 1:
        others = [(k, f) for k, _, f in tried if k != kept]
        figures["reason"] += "".join(f"; gain set {k}: {f['reason'].split(';')[0]}" for k, f in others)
    if not figures["valid"] and search is not None and residual is None and (perturb is None or guide > 0):
        t0, cpu0 = time.perf_counter(), time.process_time()
        state0 = (qpos0, qvel0)
        found = _search(scene, ref, clip, objects, state0, ref_figures, tried, gains, search, search_workers, perturb)
        wall, cpu = wall + time.perf_counter() - t0, cpu + time.process_time() - cpu0
        if found is not None and _how_far(found[2]) > _how_far(figures):
            before = figures["reason"].split(";")[0]
            kept, roll, figures = found
            if not figures["valid"]:
                figures["reason"] += f"; before the search: {before}"
        elif found is not None:  # the search's best went wrong sooner: the tried rollout stays, with what was searched
            figures = {**figures, "search": found[2]["search"]}
    figures["teacher_gains"], figures["teacher_attempts"] = kept, len(tried)
    if guide > 0:
        figures["object_guidance"] = {"scale": guide, "peak_n": perturb.peak_n}
    figures["start_prefix_s"] = prefix_frames(clip) / clip.fps
    roll.seconds = wall
    figures["realtime_factor"] = roll.frames / clip.fps / max(wall, 1e-9)
    # CPU time of this (single-threaded) process
    figures["realtime_factor_per_core"] = roll.frames / clip.fps / max(cpu, 1e-9)
    provenance = {
        "teacher": teacher,
        **({"teacher_sha256": spec.digest} if spec.digest else {}),
        "actuator_profile": profile,
        "reference": reference,
        "teacher_gains": kept,
    }
    robot = _simulated_clip(
        clip, scene, roll, "lessmimic-wbc" + ("+residual" if residual is not None else ""), provenance
    )
    return robot, roll, figures, com_series(clip, scene, ref, zmp, roll)


def _simulated_clip(clip: RobotClip, scene, roll: Rollout, method: str, provenance: dict) -> RobotClip:
    """The clip as simulated: the robot's and the objects' simulated motion, the contacts measured."""
    T = roll.frames
    sim_objects = tuple(
        replace(
            o,
            pose=roll.qpos[:, scene.object_qpos_adr[o.name] : scene.object_qpos_adr[o.name] + FREE_NQ],
            contact=None if o.contact is None else o.contact[:T],
        )
        for o in clip.objects
    )
    return RobotClip(
        roll.qpos[:, :NQ_ROBOT],
        clip.fps,
        clip.source,
        objects=sim_objects,
        contact_links=clip.contact_links,
        contacts=roll.contact if clip.contact_links else None,
        method=method,
        task=clip.task,
        provenance={**clip.provenance, **provenance},
    )
