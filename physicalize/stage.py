"""The physicalize stage: ``datasets/<NAME>/retargeted/`` -> ``datasets/<NAME>/physicalized/`` (LeRobot) +
``report.json``, and per clip an MCAP log and a PNG plot in ``logs/physicalized/``.

Each clip is physicalized by :func:`physicalize.clip.physicalize_clip` (the teacher's closed-loop tracking of
its feasible reference, validated); the clips are independent, so they run in worker processes or on Ray
(``jobs``, ``executor``), each kept as it finishes so that an interrupted run resumes (:mod:`pipeline.stage.run`);
the run is deterministic. Invalid clips stay in the report with their reason and are left out of the dataset
unless ``keep_invalid``; a clip that raises is reported invalid with the error, and the batch goes on. A rerun
on the same retargeted dataset with the same options is up to date (:func:`run_fingerprint`) and does nothing.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import asdict, dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np
from tqdm import tqdm

from physicalize.clip import TeacherSpec, load_residual, parse_teacher, physicalize_clip
from physicalize.kinematic import kinematic_clip
from physicalize.plot import plot_physicalized
from physicalize.rollout import Rollout
from physicalize.search.beam import SearchConfig
from physicalize.start import prefix_frames
from physicalize.validate import summarise
from pipeline.clip import PhysicalizedClip, RobotClip
from pipeline.dataset.card import DatasetCard
from pipeline.dataset.clips import episodes_to_robot_clips, physicalized_clips_to_episodes
from pipeline.dataset.objects import objects_note
from pipeline.dataset.ranges import check_ranges
from pipeline.dataset.schema import validate_episode
from pipeline.dataset.write import write_dataset
from pipeline.errors import InputError
from pipeline.geometry import provenance_variant
from pipeline.robot import FREE_NV, NV_ROBOT, ActuatorProfile, actuator_profile
from pipeline.stage.executor import check_executor
from pipeline.stage.inspect_log import write_robot_log
from pipeline.stage.paths import file_stem, stage_dir
from pipeline.stage.run import StageRun, digest
from pipeline.stage.state import dataset_fingerprint, fingerprint


@dataclass(frozen=True)
class ClipResult:
    """One clip's outcome: the simulated clip (``None`` if it raised), its rollout and figures."""

    index: int
    source: str
    robot: RobotClip | None
    rollout: Rollout | None
    figures: dict
    com: dict  # reference / planned / simulated CoM series for the plot


def _writable(kept: list[ClipResult], fps: float) -> list[ClipResult]:
    """The clips of ``kept`` the dataset can hold: every valid one, and an invalid one kept by ``--keep-invalid``
    only within the dataset's value ranges (:mod:`pipeline.dataset.ranges`, which the writer refuses a dataset for);
    the reason of one that is not says so, and it is reported, not written. Why: a rollout that fell can fling a
    joint far past its stop (measured: the hand-made teleport clip's wrist 0.75 rad past it), and one kept failure
    must not refuse the dataset of every valid clip."""
    writable = []
    for r in kept:
        if not r.figures["valid"]:
            features, episodes = physicalized_clips_to_episodes([_physicalized(r)])
            try:
                check_ranges(validate_episode(features, episodes[0], r.source), fps, r.source)
            except InputError as e:
                r.figures["reason"] += f"; not written (--keep-invalid): {str(e).removeprefix(r.source + ': ')}"
                continue
        writable.append(r)
    return writable


def physicalize_one(
    item: tuple[int, RobotClip],
    teacher: str = "base",
    profile: str = "mjlab",
    search: SearchConfig | None = None,
    search_workers: int = 1,
) -> ClipResult:
    """:func:`physicalize_clip` of the ``(index, clip)`` item with the ``search`` where the teacher falls (None: no
    search; its children in ``search_workers`` processes); a clip that raises is invalid, with its error."""
    index, clip = item
    kw = {"teacher": teacher, "search": search, "search_workers": search_workers}
    run = kinematic_clip if teacher == "kinematic" else partial(physicalize_clip, **kw)
    try:
        robot, roll, figures, com = run(clip, profile=profile)
    except Exception as exc:  # noqa: BLE001 - a clip that cannot be simulated is reported, the batch goes on
        reason = f"error: {type(exc).__name__}: {exc}"
        return ClipResult(index, clip.source, None, None, {"valid": False, "reason": reason, "failure": "error"}, {})
    return ClipResult(index, clip.source, robot, roll, figures, {"reference_qpos": clip.qpos, **com})


def _clip_key(k: int, item: tuple[int, RobotClip]) -> str:
    clip = item[1]
    return digest(
        k, clip.source, clip.qpos, *(p for o in clip.objects for p in (o.pose, o.mass, o.friction, o.floor_friction))
    )


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


def run_fingerprint(src: Path, spec: TeacherSpec, profile: str, keep_invalid: bool, search: SearchConfig | None) -> str:
    """What a run's output depends on (:mod:`pipeline.stage.state`): the retargeted dataset at ``src``,
    the teacher (with its checkpoint's digest, not its path), the actuator profile, ``keep_invalid`` and the search."""
    return fingerprint(
        stage="physicalized",
        retargeted=dataset_fingerprint(src),
        teacher=spec.name,
        teacher_sha256=spec.digest,
        actuator_profile=profile,
        keep_invalid=keep_invalid,
        search=None if search is None else asdict(search),
    )


def search_workers(jobs: int, clips: int, executor: str = "local") -> int:
    """The processes each clip's search spreads its children over (:mod:`physicalize.search.children`): the jobs
    the clips leave idle, ``jobs // clips`` (at least 1), so that ``--jobs`` cores are busy however few clips there
    are; 1 on Ray, whose tasks each hold one CPU."""
    return 1 if executor != "local" else max(1, jobs // max(clips, 1))


def search_config(budget: float | None) -> SearchConfig | None:
    """The search of ``--search-budget`` (children per second of motion; None: the default, 0: no search); a budget
    below 0 or not finite is an :class:`InputError`."""
    if budget is None:
        return SearchConfig()
    if not math.isfinite(budget) or budget < 0:
        raise InputError(budget, "--search-budget", "must be >= 0 children per second of motion (0: no search)")
    return replace(SearchConfig(), children_per_s=budget) if budget > 0 else None


def _checked_teacher(teacher: str, profile: str) -> tuple[TeacherSpec, ActuatorProfile]:
    """The parsed teacher and actuator profile, or one :class:`InputError` line (unknown profile, unreadable
    residual checkpoint, or one trained for another profile)."""
    spec = parse_teacher(teacher)
    try:
        prof = actuator_profile(profile)
    except ValueError as exc:
        raise InputError(profile, "--profile", str(exc)) from None
    if spec.checkpoint is not None:
        try:
            trained_for = load_residual(str(spec.checkpoint), spec.digest).cfg.profile
        except Exception as exc:  # noqa: BLE001 - any unreadable checkpoint is a one-line input error
            why = f"unreadable residual checkpoint: {type(exc).__name__}: {exc}"
            raise InputError(spec.checkpoint, "--teacher", why) from None
        if trained_for != prof.name:
            why = f"residual trained for actuator profile {trained_for!r}, this run uses {prof.name!r}"
            raise InputError(spec.checkpoint, "--teacher", why)
    return spec, prof


def yield_table(per_clip: list[dict]) -> dict:
    """Per task and geometry variant (``"PickUp x0.6"``; a corpus without variants: per task): ``clips``, ``valid``,
    and the invalid ones by class, ``rejected`` (the plan refused them: physicalize.feasibility) and ``failed`` (the
    simulation did not hold: physicalize.validate), so a reader sees where the robot's own limits are;
    ``payload_capped``: the valid ones whose held object was made lighter for the motors (physicalize.payload)."""
    out: dict[str, dict] = {}
    for c in per_clip:
        key = " ".join(k for k in (c.get("task") or "no task", c.get("variant")) if k)
        row = out.setdefault(key, {"clips": 0, "valid": 0, "payload_capped": 0, "rejected": {}, "failed": {}})
        row["clips"] += 1
        row["valid"] += bool(c["valid"])
        row["payload_capped"] += bool(c["valid"] and c.get("payload_capped"))
        for kind in ("rejected", "failure"):
            if why := c.get(kind):
                table = row["rejected" if kind == "rejected" else "failed"]
                table[why] = table.get(why, 0) + 1
    return dict(sorted(out.items()))


def _report(
    results: list[ClipResult], clips: list[RobotClip], spec: TeacherSpec, teacher: str, prof, keep_invalid, kept: int
) -> dict:
    per_clip = [
        {
            "episode": r.index,
            "source": r.source,
            "task": clips[r.index].task,
            **({"variant": v} if (v := provenance_variant(clips[r.index].provenance)) else {}),
            **r.figures,
        }
        for r in results
    ]
    simulated = sum(r.rollout.frames for r in results if r.rollout is not None) / clips[0].fps if clips else 0.0
    seconds = sum(r.rollout.seconds for r in results if r.rollout)
    return {
        "stage": "physicalized",
        "teacher": teacher,
        "teacher_sha256": spec.digest,
        "actuator_profile": prof.name,
        "keep_invalid": keep_invalid,
        "clips": per_clip,
        "summary": {
            **summarise([c for c in per_clip if "frames" in c] or per_clip),
            "valid_frac": float(np.mean([c["valid"] for c in per_clip])) if per_clip else 0.0,
            "clips_rejected": dict(Counter(c["rejected"] for c in per_clip if c.get("rejected"))),
            "clips_failed": dict(Counter(c["failure"] for c in per_clip if c.get("failure"))),
            "realtime_factor": simulated / max(seconds, 1e-9),
            "episodes_written": kept,
        },
        "yield": yield_table(per_clip),
    }


KINEMATIC_NOTE = (
    "Teacher `kinematic` (physicalize.kinematic): the data of LessMimic's 'Ours - Syn.' ablation (raw retargeted "
    "mocap instead of physicalized data). `observation.state` is the retargeted qpos, `observation.qvel` its central "
    "differences, `action` the next frame's joint positions, `observation.torque` zero; `valid` is True for every "
    "clip and `physics_valid` says whether its poses pass the simulated clips' bars."
)


def _card(name: str, kept: list[ClipResult], src: Path, spec: TeacherSpec, teacher: str, prof, features) -> DatasetCard:
    if teacher == "kinematic":
        title = f"{name}: G1 retargeted motion in the physicalized layout (NOT simulated: the -Syn ablation)"
        what = (
            "retargeted G1 motion as it is, with finite-difference velocities and the next frame's joints as the "
            "action (teacher `kinematic`); nothing is simulated. Every episode carries the physics figures measured "
            "on its poses (`physics_valid`, `physics_reason`)."
        )
        notes = [KINEMATIC_NOTE]
    else:
        title = f"{name}: G1 physicalized state-action data"
        what = (
            f"retargeted G1 motion made physically valid by closed-loop tracking in MuJoCo (teacher `{teacher}`: "
            "whole-body QP" + (" + learned residual" if spec.digest else "") + "); every episode carries its "
            "validation figures."
        )
        teacher_note = f"Teacher: `{teacher}`" + (
            f" (checkpoint sha256 {spec.digest}): the base QP controller's joint targets plus a learned "
            "residual (PPO, physicalize.residual), used deterministically (mean action)."
            if spec.digest
            else "."
        )
        notes = CARD_NOTES + [teacher_note]
    synthetic = any(r.robot.provenance.get("synthetic") for r in kept)
    return DatasetCard(
        title=title,
        description=("SYNTHETIC demonstrations: " if synthetic else "") + what,
        provenance=[r.source for r in kept] + [str(src)],
        fps=int(round(kept[0].robot.fps)),
        synthetic=synthetic,
        stage="physicalized",
        actuator_profile=f"{prof.name}: {prof.description}",
        license="apache-2.0" if synthetic else "other",
        feature_frames={f.name: "world, z-up" if f.name.startswith("object") else "" for f in features},
        notes=notes + [objects_note([r.robot for r in kept])],
    )


def _write_logs(results: list[ClipResult], clips: list[RobotClip], logs: Path) -> None:
    """Per simulated clip: its MCAP log and its plot (CoM, foot forces, object heights, the verdict)."""
    for r in tqdm([r for r in results if r.robot is not None], desc="logs and plots", unit="clip"):
        stem = f"{r.index:03d}_{file_stem(r.source)}"
        write_robot_log(r.robot, logs / f"{stem}.mcap")
        n = prefix_frames(r.robot)  # the reference holds the object where it starts over a start prefix
        objs = {
            o.name: (np.pad(clips[r.index].objects[k].pose[:, 2], (n, 0), mode="edge"), o.pose[:, 2])
            for k, o in enumerate(r.robot.objects)
        }
        verdict = "valid" if r.figures["valid"] else "INVALID: " + r.figures["reason"]
        title = f"{r.source} ({r.robot.task or 'no task'}): {verdict}"
        plot_physicalized(r.com, r.rollout.foot_force, objs, r.robot.fps, title[:150], logs / f"{stem}.png")


def run_stage(
    name: str,
    *,
    overwrite: bool = False,
    teacher: str = "base",
    profile: str = "mjlab",
    keep_invalid: bool = False,
    jobs: int = 1,
    executor: str = "local",
    search_budget: float | None = None,
) -> dict:
    """``lessmimic physicalize``: simulate every retargeted clip (the search of ``search_budget``,
    :func:`search_config`, where the teacher falls), write the dataset, report and logs. Without
    ``overwrite``, a finished run on the same retargeted dataset with the same options (:func:`run_fingerprint`)
    is up to date: its report comes back with ``"up_to_date": True`` and nothing is done."""
    check_executor(executor, jobs)
    spec, prof = _checked_teacher(teacher, profile)
    search = search_config(search_budget)
    src = stage_dir(name, "retargeted")
    if not (src / "meta" / "info.json").is_file():
        why = "no retargeted dataset here: run `lessmimic retarget --name NAME` first"
        raise InputError(src, "meta/info.json", why)
    run = StageRun(stage_dir(name, "physicalized"), run_fingerprint(src, spec, prof.name, keep_invalid, search))
    if not overwrite and (done := run.finished()) is not None:
        return {**done, "up_to_date": True}
    run.begin(overwrite)
    t0 = time.perf_counter()
    clips = episodes_to_robot_clips(src)
    workers = search_workers(jobs, len(clips), executor)
    simulate = partial(physicalize_one, teacher=teacher, profile=prof.name, search=search, search_workers=workers)
    results = run.map(simulate, list(enumerate(clips)), key=_clip_key, jobs=jobs, executor=executor, desc="physicalize")
    kept = _writable([r for r in results if r.robot is not None and (r.figures["valid"] or keep_invalid)], clips[0].fps)
    report = _report(results, clips, spec, teacher, prof, keep_invalid, len(kept))
    for c in report["clips"]:
        if not c["valid"]:
            print(f"invalid: {c['source']}: {c['reason']}")
    if kept:
        features, episodes = physicalized_clips_to_episodes([_physicalized(r) for r in kept])
        card = _card(name, kept, src, spec, teacher, prof, features)
        write_dataset(
            run.out,
            f"lessmimic/{name}-physicalized",
            int(round(clips[0].fps)),
            features,
            episodes,
            card=card,
            overwrite=run.replaces,
        )
    _write_logs(results, clips, run.logs)
    return run.finish({**report, "seconds_wall": time.perf_counter() - t0}, dataset_written=bool(kept))
