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
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

from physicalize.clip import TeacherSpec, load_residual, parse_teacher, physicalize_clip
from physicalize.rollout import Rollout
from pipeline.clip import PhysicalizedClip, RobotClip
from pipeline.errors import InputError
from pipeline.robot import FREE_NV, NV_ROBOT

if TYPE_CHECKING:
    pass


@dataclass(frozen=True)
class ClipResult:
    """One clip's outcome: the simulated clip (``None`` if it raised), its rollout and figures."""

    index: int
    source: str
    robot: RobotClip | None
    rollout: Rollout | None
    figures: dict
    com: dict  # reference / planned / simulated CoM series for the plot


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
            trained_for = load_residual(str(spec.checkpoint), spec.digest).cfg.profile
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
