"""The physicalize stage: ``datasets/<NAME>/retargeted/`` -> ``datasets/<NAME>/physicalized/``
(LeRobot) + ``report.json``, and per clip an MCAP log and a PNG plot in ``logs/physicalized/``.

Per clip: build the scene (robot + objects as free bodies moved only by contact), the tracking
reference (:mod:`physicalize.reference`), the feasible CoM plan (:mod:`physicalize.plan`) with the
whole body re-solved onto it (:mod:`physicalize.feasible`), track it
closed loop with the teacher (``base``: :class:`physicalize.wbc.WholeBodyController`), record the
state-action trajectory (:mod:`physicalize.rollout`), replay the actions open loop to check
self-consistency, and measure the validity figures (:mod:`physicalize.validate`); the base teacher tries
its QP gain sets (:data:`physicalize.wbc_config.TEACHER_GAINS`) in order until a rollout is valid. Invalid clips stay
in the report with their reason and are left out of the dataset unless ``keep_invalid``. A clip
that raises is reported invalid with the error; the batch goes on. Finished clips are cached in
``datasets/<NAME>/.work/physicalize/`` so an interrupted run resumes; the run is deterministic. A
rerun on the same retarget dataset with the same options is up to date (:func:`run_fingerprint`,
recorded in ``logs/physicalized/report.json``) and does nothing.
"""

from __future__ import annotations

import hashlib
import pickle
import shutil
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

from physicalize.rollout import Rollout
from pipeline.clip import PhysicalizedClip, RobotClip
from pipeline.errors import InputError
from pipeline.robot import FREE_NV, NQ_ROBOT, NV_ROBOT

if TYPE_CHECKING:
    from physicalize.wbc_config import WBCConfig

TEACHERS = ("base", "base+residual:<checkpoint>")
REPLAY_TOL_M = 1e-6
NO_RETRY_GRIP_OUT = (
    0.5  # share of held frames whose planned hand forces leave the friction cones (the InterMimic table: 0.85)
)


@dataclass(frozen=True)
class TeacherSpec:
    """A parsed ``--teacher``: the base QP controller, optionally with a learned residual checkpoint
    (``digest``: the checkpoint file's sha256, part of the cache key and the provenance)."""

    name: str
    checkpoint: Path | None = None
    digest: str | None = None


def parse_teacher(teacher: str) -> TeacherSpec:
    """``base`` or ``base+residual:<checkpoint path>``; anything else, or a checkpoint that is not a
    file, is an :class:`InputError` (one line naming the teacher or the path)."""
    if teacher == "base":
        return TeacherSpec("base")
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


def _load_residual(path: str, digest: str):
    """The checkpoint's policy, loaded once per (path, content)."""
    if (path, digest) not in _RESIDUALS:
        from physicalize.residual import ResidualPolicy

        _RESIDUALS[(path, digest)] = ResidualPolicy.load(path)
    return _RESIDUALS[(path, digest)]


@dataclass(frozen=True)
class ClipResult:
    """One clip's outcome: the simulated clip (``None`` if it raised), its rollout and figures."""

    index: int
    source: str
    robot: RobotClip | None
    rollout: Rollout | None
    figures: dict
    com: dict  # reference / planned / simulated CoM series for the plot


def _scene_for(clip: RobotClip, profile: str):
    from pipeline.scene import SceneObject, build_scene

    return build_scene(
        [SceneObject(o.name, o.geometry, o.physics(), pose=tuple(o.pose[0])) for o in clip.objects], profile
    )


REFERENCES = ("raw", "planned", "feasible")


def tracking_problem(clip: RobotClip, profile: str = "mjlab", reference: str = "feasible", grasp: bool = True):
    """``(scene, tracked Reference, object tracks {name: (T, 7)}, planned ZMP or None)`` of one clip,
    tracking the ``reference``: ``raw`` (the retargeted motion and its kinematic CoM), ``planned`` (its
    posture with the ZMP-planned CoM) or ``feasible`` (the whole body re-solved by IK onto the plan);
    with ``grasp``, hands that hold an object squeeze it and carry its weight (:mod:`physicalize.grasp`).
    Shared by :func:`physicalize_clip` and the residual's training (:mod:`physicalize.residual`)."""
    from physicalize.feasible import feasible_reference
    from physicalize.grasp import grasp_schedule
    from physicalize.plan import HandLoads, plan_com
    from physicalize.reference import build_reference
    from physicalize.seat import seat_support

    if reference not in REFERENCES:
        raise ValueError(f"unknown reference {reference!r}; known: {', '.join(REFERENCES)}")
    scene = _scene_for(clip, profile)
    ref = build_reference(scene.model, clip.qpos, clip.fps)
    zmp = None
    m = scene.model
    obj_q = np.repeat(m.qpos0[None, NQ_ROBOT:], ref.frames, 0)
    for o in (o for o in clip.objects if o.name in scene.object_qpos_adr):  # free objects; fixed ones are in the model
        adr = scene.object_qpos_adr[o.name] - NQ_ROBOT
        obj_q[:, adr : adr + 7] = o.pose[: ref.frames]
    ref.seat = seat_support(m, ref, clip.contact_links, clip.contacts, obj_q)  # the plan's support includes the seat
    if reference == "planned":
        ref.com_plan, _, zmp = plan_com(ref)
    elif reference == "feasible":
        stats: dict = {}
        hands = pre = None
        # hands held on an object move with its reference track (the retargeted hands drift off it): the IK re-solves
        # the arms onto that
        if grasp:
            pre = grasp_schedule(scene, ref, clip.contact_links, clip.contacts, {o.name: o.pose for o in clip.objects})
            hands = None if pre is None else pre.hand_body_targets()
        plan_fn = (
            plan_com
            if pre is None
            else partial(
                plan_com, loads=HandLoads(pre.attached, pre.force, float(m.body_subtreemass[m.body("pelvis").id]))
            )
        )
        seat = ref.seat
        ref = feasible_reference(
            m, ref, plan_fn, stats=stats, objects=obj_q if clip.objects else None, hand_targets=hands
        )
        ref.seat = seat
        zmp = stats["plan"][2]
    objects = {o.name: o.pose for o in clip.objects}
    if grasp:
        ref.grasp = grasp_schedule(scene, ref, clip.contact_links, clip.contacts, objects)
    return scene, ref, objects, zmp


def _reference_figures(scene, ref, fps: float) -> tuple[dict, str]:
    """What the tracked reference asks beyond the robot, the same for every rollout of it: the static
    upper-body torque (:mod:`physicalize.static_torque`) and the share of held frames whose planned hand
    forces leave the friction cones; with the cause an invalid rollout's reason names ("" when none)."""
    from physicalize.static_torque import static_torque_figures

    loads = None if ref.grasp is None else (ref.grasp.offset, ref.grasp.force)
    figures = static_torque_figures(
        ref.qpos, loads, scene.profile.effort_limit, fps
    )  # what the reference asks of the upper body
    if ref.grasp is None:
        held = outside = np.zeros(0, bool)
    else:
        held = ref.grasp.grasped.any(axis=1)
        outside = held & ~ref.grasp.friction_ok
    figures["reference_grasp_outside_friction_frac"] = float(outside.sum() / max(held.sum(), 1))  # of the held frames
    cause = (
        f"; the hands' planned force leaves their friction cones from t={np.flatnonzero(outside)[0] / fps:.2f} s"
        if outside.any()
        else ""
    )
    return figures, cause  # a cause no controller can overcome


def _figures(
    scene, roll: Rollout, clip: RobotClip, objects, qpos0, qvel0, perturb, reference: tuple[dict, str]
) -> dict:
    """The validity figures of one rollout (:mod:`physicalize.validate`), its reference's figures
    (:func:`_reference_figures`) and the open-loop replay check."""
    from physicalize.rollout import replay
    from physicalize.validate import validate

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
    return figures


def physicalize_clip(
    clip: RobotClip,
    *,
    profile: str = "mjlab",
    reference: str = "feasible",
    perturb=None,
    teacher: str = "base",
    grasp: bool = True,
    gains: tuple[WBCConfig, ...] | None = None,
) -> tuple[RobotClip | None, Rollout, dict, dict]:
    """(simulated clip, rollout, validity figures, CoM series) of one retargeted clip tracking the
    ``reference`` (see :func:`tracking_problem`) with the ``teacher`` (see :func:`parse_teacher`).

    The base teacher tries the QP gain sets ``gains`` (default :data:`physicalize.wbc_config.TEACHER_GAINS`) in
    order from the same initial state and keeps the first rollout that is valid, else the first set's:
    rejection sampling over controller gains, each rollout validated on its own. A reference whose hands
    must push outside their friction cones on most held frames (> :data:`NO_RETRY_GRIP_OUT`) is not
    retried: no gains make a pressing hand pull. ``figures`` name the set
    kept (``teacher_gains``, its index) and how many ran (``teacher_attempts``); timings count them all.
    A residual teacher runs the first set only (its policy was trained on it)."""
    from physicalize.rollout import initial_state, simulate
    from physicalize.wbc import WholeBodyController
    from physicalize.wbc_config import TEACHER_GAINS

    spec = parse_teacher(teacher)
    residual = None if spec.checkpoint is None else _load_residual(str(spec.checkpoint), spec.digest)
    gains = (TEACHER_GAINS if gains is None else tuple(gains))[: 1 if residual is not None else None]
    t0, cpu0 = time.perf_counter(), time.process_time()
    scene, ref, objects, zmp = tracking_problem(clip, profile, reference, grasp)
    qpos0, qvel0 = initial_state(scene, ref, objects)
    tried, wall, cpu = (
        [],
        time.perf_counter() - t0,
        time.process_time() - cpu0,
    )  # planning + tracking, every attempt (not the checks)
    ref_figures = _reference_figures(scene, ref, clip.fps)
    if ref_figures[0]["reference_grasp_outside_friction_frac"] > NO_RETRY_GRIP_OUT:
        gains = gains[:1]  # no gains make a pressing hand pull
    for config in gains:
        t0, cpu0 = time.perf_counter(), time.process_time()
        roll = simulate(
            scene,
            ref,
            WholeBodyController(scene.model, scene.profile, config),
            qpos0,
            qvel0,
            contact_links=clip.contact_links,
            perturb=perturb,
            residual=residual,
        )
        wall, cpu = wall + time.perf_counter() - t0, cpu + time.process_time() - cpu0
        tried.append((roll, _figures(scene, roll, clip, objects, qpos0, qvel0, perturb, ref_figures)))
        if tried[-1][1]["valid"]:
            break
    kept = len(tried) - 1 if tried[-1][1]["valid"] else 0
    roll, figures = tried[kept]
    if not figures["valid"] and len(tried) > 1:
        figures["reason"] += "".join(
            f"; gain set {k}: {f['reason'].split(';')[0]}" for k, (_, f) in enumerate(tried[1:], 1)
        )
    figures["teacher_gains"], figures["teacher_attempts"] = kept, len(tried)
    roll.seconds = wall
    figures["realtime_factor"] = roll.frames / clip.fps / max(wall, 1e-9)
    figures["realtime_factor_per_core"] = (
        roll.frames / clip.fps / max(cpu, 1e-9)
    )  # CPU time of this (single-threaded) process
    T = roll.frames
    sim_objects = tuple(
        replace(
            o,
            pose=roll.qpos[:, scene.object_qpos_adr[o.name] : scene.object_qpos_adr[o.name] + 7],
            contact=None if o.contact is None else o.contact[:T],
        )
        for o in clip.objects
    )
    robot = RobotClip(
        roll.qpos[:, :NQ_ROBOT],
        clip.fps,
        clip.source,
        objects=sim_objects,
        contact_links=clip.contact_links,
        contacts=roll.contact if clip.contact_links else None,
        method="lessmimic-wbc" + ("+residual" if residual is not None else ""),
        task=clip.task,
        provenance={
            **clip.provenance,
            "teacher": teacher,
            **({"teacher_sha256": spec.digest} if spec.digest else {}),
            "actuator_profile": profile,
            "reference": reference,
            "teacher_gains": kept,
        },
    )
    com = {
        "reference": ref.com[:T],
        "planned": (ref.com if ref.com_plan is None else ref.com_plan)[:T],
        "zmp_planned": None if zmp is None else zmp[:T],
        "simulated": _sim_com(scene.model, roll.qpos),
        "pelvis_ref": clip.qpos[:T, 2],
        "pelvis_sim": roll.qpos[:, 2],
        "support": _support_box(ref)[:T],
    }
    return robot, roll, figures, com


def _support_box(ref) -> np.ndarray:
    """(T, 2, 2) per frame the [min, max] x and y of the stance feet's sole corners (the support region's bounds)."""
    corners = np.where(ref.stance[:, :, None, None], ref.corners[..., :2], np.nan).reshape(ref.frames, -1, 2)
    return np.stack([np.nanmin(corners, axis=1), np.nanmax(corners, axis=1)], axis=1)


def _sim_com(model, qpos: np.ndarray) -> np.ndarray:
    import mujoco

    d = mujoco.MjData(model)
    out = np.zeros((len(qpos), 3))
    for t, q in enumerate(qpos):
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        out[t] = d.subtree_com[model.body("pelvis").id]
    return out


def _cache_key(clip: RobotClip, index: int, teacher: str, profile: str) -> str:
    h = hashlib.sha256(np.ascontiguousarray(clip.qpos).tobytes())
    for o in clip.objects:
        h.update(np.ascontiguousarray(o.pose).tobytes())
        h.update(f"{o.mass}|{o.friction}".encode())
    h.update(f"{clip.source}|{index}|{teacher}|{parse_teacher(teacher).digest}|{profile}".encode())
    return h.hexdigest()[:16]


def _run_one(index: int, clip: RobotClip, work: Path, teacher: str, profile: str) -> ClipResult:
    cached = work / f"{_cache_key(clip, index, teacher, profile)}.pkl"
    if cached.is_file():
        return pickle.loads(cached.read_bytes())
    try:
        robot, roll, figures, com = physicalize_clip(clip, profile=profile, teacher=teacher)
        result = ClipResult(index, clip.source, robot, roll, figures, com)
    except Exception as exc:  # noqa: BLE001 - a clip that cannot be simulated is reported, the batch goes on
        result = ClipResult(
            index, clip.source, None, None, {"valid": False, "reason": f"error: {type(exc).__name__}: {exc}"}, {}
        )
    tmp = cached.with_suffix(".tmp")
    tmp.write_bytes(pickle.dumps(result))
    tmp.replace(cached)
    return result


CARD_NOTES = [
    "Each episode is a closed-loop MuJoCo simulation (200 Hz physics, 50 Hz control) of the G1 tracking a retargeted "
    "clip with a training-free whole-body QP controller (the `base` teacher) on a dynamically feasible reference (a "
    "ZMP preview-control CoM plan over the clip's foot support schedule, the whole body re-solved onto it by IK "
    "keeping the footsteps, hands and posture). Objects are free bodies moved only by contact: no welds, no external "
    "or root assist forces. The controller's QP gain sets are tried in order per clip and the first valid rollout is "
    "kept (its index: `teacher_gains` in the episode's validation figures).",
    "`action` is the 29 joint position targets the position actuators held from frame t to t+1 (actuator profile in "
    "the card header); `observation.torque` the actuator torques applied (mean over the 4 physics steps of the hold).",
    "`observation.state`/`observation.qvel` are the simulation's qpos/qvel (root linear velocity world frame, root "
    "angular velocity body frame); `reference.state` the retargeted qpos the controller tracked.",
    "Replaying `action` open loop from the first frame's state (and the objects' first poses, at rest) in MuJoCo "
    "reproduces the states (checked per clip: `replay_err_max_m` in report.json).",
    "Per-clip validity figures are in each episode's metadata and in `report.json`; invalid clips are not in the "
    "dataset unless the stage ran with --keep-invalid.",
]


def _physicalized(r: ClipResult) -> PhysicalizedClip:
    """The clip as the dataset stores it: the simulated motion and what the simulation measured."""
    roll, T = r.rollout, r.robot.frames
    vel = tuple(
        roll.qvel[:, NV_ROBOT + FREE_NV * k : NV_ROBOT + FREE_NV * (k + 1)] for k in range(len(r.robot.objects))
    )
    return PhysicalizedClip(
        r.robot,
        roll.qvel[:, :NV_ROBOT],
        vel,
        roll.action,
        roll.torque,
        roll.foot_force,
        r.com["reference_qpos"][:T],
        r.figures,
    )


def run_fingerprint(src: Path, spec: TeacherSpec, profile: str, keep_invalid: bool) -> str:
    """What a run's output depends on (:mod:`pipeline.stage.state`): the retargeted dataset at ``src``,
    the teacher (with its checkpoint's digest, not its path), the actuator profile and ``keep_invalid``."""
    from pipeline.stage.state import dataset_fingerprint, fingerprint

    return fingerprint(
        stage="physicalized",
        retargeted=dataset_fingerprint(src),
        teacher=spec.name,
        teacher_sha256=spec.digest,
        actuator_profile=profile,
        keep_invalid=keep_invalid,
    )


def run_stage(
    name: str, *, overwrite: bool = False, teacher: str = "base", profile: str = "mjlab", keep_invalid: bool = False
) -> dict:
    """``lessmimic physicalize``: simulate every retargeted clip, write the dataset, report and logs.
    Without ``overwrite``, a run whose logs report records this run's :func:`run_fingerprint`, and whose
    dataset exists (or kept no clip), is up to date: that report comes back with ``"up_to_date": True``
    and nothing is done."""
    from physicalize.plot import plot_physicalized
    from physicalize.validate import summarise
    from pipeline.dataset.card import DatasetCard
    from pipeline.dataset.clips import episodes_to_robot_clips, physicalized_clips_to_episodes
    from pipeline.dataset.write import check_target, write_dataset
    from pipeline.robot import actuator_profile
    from pipeline.stage.atomic import write_json_atomic
    from pipeline.stage.inspect_log import write_robot_log
    from pipeline.stage.paths import file_stem, stage_dir
    from pipeline.stage.state import KEY, up_to_date

    spec = parse_teacher(teacher)
    try:
        prof = actuator_profile(profile)
    except ValueError as exc:
        raise InputError(profile, "--profile", str(exc)) from None
    if spec.checkpoint is not None:
        try:
            trained_for = _load_residual(str(spec.checkpoint), spec.digest).cfg.profile
        except Exception as exc:  # noqa: BLE001 - any unreadable checkpoint is a one-line input error
            raise InputError(
                spec.checkpoint, "--teacher", f"unreadable residual checkpoint: {type(exc).__name__}: {exc}"
            ) from None
        if trained_for != prof.name:
            raise InputError(
                spec.checkpoint,
                "--teacher",
                f"residual trained for actuator profile {trained_for!r}, this run uses {prof.name!r}",
            )
    src, out = stage_dir(name, "retargeted"), stage_dir(name, "physicalized")
    if not (src / "meta" / "info.json").is_file():
        raise InputError(
            src, "meta/info.json", "no retargeted dataset here: run `lessmimic retarget --name NAME` first"
        )
    fp, logs = run_fingerprint(src, spec, prof.name, keep_invalid), out.parent / "logs" / "physicalized"
    recorded = None if overwrite else up_to_date(logs / "report.json", fp)
    if recorded is not None and (out.is_dir() or not recorded["summary"].get("episodes_written")):
        return {**recorded, "up_to_date": True}
    check_target(out, overwrite)
    clips = episodes_to_robot_clips(src)
    t0 = time.perf_counter()
    work = out.parent / ".work" / "physicalize"
    if overwrite:
        shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True, exist_ok=True)
    results = [
        _run_one(i, c, work, teacher, prof.name) for i, c in enumerate(tqdm(clips, desc="physicalize", unit="clip"))
    ]
    for r, c in zip(results, clips):
        if r.com:
            r.com["reference_qpos"] = c.qpos
    per_clip = [{"episode": r.index, "source": r.source, "task": clips[r.index].task, **r.figures} for r in results]
    kept = [r for r in results if r.robot is not None and (r.figures["valid"] or keep_invalid)]
    simulated = sum(r.rollout.frames for r in results if r.rollout is not None) / clips[0].fps if clips else 0.0
    report = {
        "stage": "physicalized",
        "teacher": teacher,
        "teacher_sha256": spec.digest,
        "actuator_profile": prof.name,
        "keep_invalid": keep_invalid,
        "clips": per_clip,
        "summary": {
            **summarise([c for c in per_clip if "frames" in c] or per_clip),
            "valid_frac": float(np.mean([c["valid"] for c in per_clip])) if per_clip else 0.0,
            "realtime_factor": simulated / max(sum(r.rollout.seconds for r in results if r.rollout), 1e-9),
            "episodes_written": len(kept),
        },
        KEY: fp,
    }
    for c in per_clip:
        if not c["valid"]:
            print(f"invalid: {c['source']}: {c['reason']}")
    if kept:
        fps = int(round(clips[0].fps))
        features, episodes = physicalized_clips_to_episodes([_physicalized(r) for r in kept])
        teacher_note = f"Teacher: `{teacher}`" + (
            f" (checkpoint sha256 {spec.digest}): the base QP controller's joint targets plus a learned "
            "residual (PPO, physicalize.residual), used deterministically (mean action)."
            if spec.digest
            else "."
        )
        synthetic = any(r.robot.provenance.get("synthetic") for r in kept)
        card = DatasetCard(
            title=f"{name}: G1 physicalized state-action data",
            description=("SYNTHETIC demonstrations: " if synthetic else "")
            + "retargeted G1 motion made physically valid by "
            f"closed-loop tracking in MuJoCo (teacher `{teacher}`: whole-body QP"
            + (" + learned residual" if spec.digest else "")
            + "); every episode carries its validation figures.",
            provenance=[r.source for r in kept] + [str(src)],
            fps=fps,
            synthetic=synthetic,
            stage="physicalized",
            actuator_profile=f"{prof.name}: {prof.description}",
            license="apache-2.0" if synthetic else "other",
            feature_frames={f.name: "world, z-up" if f.name.startswith("object.") else "" for f in features},
            notes=CARD_NOTES + [teacher_note],
        )
        write_dataset(out, f"lessmimic/{name}-physicalized", fps, features, episodes, card=card, overwrite=overwrite)
    elif out.is_dir():  # --overwrite and nothing kept: the old dataset is not this run's output
        shutil.rmtree(out)
    for r in tqdm([r for r in results if r.robot is not None], desc="logs and plots", unit="clip"):
        stem = f"{r.index:03d}_{file_stem(r.source)}"
        write_robot_log(r.robot, logs / f"{stem}.mcap")
        objs = {o.name: (clips[r.index].objects[k].pose[:, 2], o.pose[:, 2]) for k, o in enumerate(r.robot.objects)}
        verdict = "valid" if r.figures["valid"] else "INVALID: " + r.figures["reason"]
        title = f"{r.source} ({r.robot.task or 'no task'}): {verdict}"
        plot_physicalized(r.com, r.rollout.foot_force, objs, r.robot.fps, title[:150], logs / f"{stem}.png")
    report["seconds_wall"] = time.perf_counter() - t0
    if kept:
        write_json_atomic(out / "report.json", report)
    write_json_atomic(
        logs / "report.json", report
    )  # also where it lives when no clip was valid; last: its fingerprint marks a finished run
    shutil.rmtree(work, ignore_errors=True)
    return report
