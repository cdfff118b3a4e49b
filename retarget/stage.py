"""The retarget stage: every human clip of the input -> a G1 :class:`RobotClip`, written as
``datasets/<NAME>/retargeted/`` (LeRobot) with ``report.json``, and per clip an MCAP log and a
PNG plot (:mod:`retarget.plot`) in ``datasets/<NAME>/logs/retargeted/``.

Per clip (independent, so a process pool runs them): resample the human clip to the control
rate (:data:`FPS`), pick its mapping, compute the scale, build :class:`IKTargets`, map the
objects into the robot's world, solve the IK in a scene built with the same collision model
as the physics, label per-link contacts from the human's, and measure
:func:`retarget.metrics.retarget_metrics`. A finished clip is cached in
``datasets/<NAME>/.work/retarget/`` (keyed by the clip's data and index), so a re-run after an
interruption resumes where it stopped (``--overwrite`` starts afresh; a finished stage removes
the cache); a failing clip is reported with its one-line error and the others go on. A rerun on
the same input with the same options finds the dataset up to date (:func:`input_fingerprint`,
recorded in ``report.json``) and does nothing.
"""

from __future__ import annotations

import hashlib
import pickle
import shutil
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pipeline.clip import HumanClip, RobotClip
from pipeline.errors import InputError
from pipeline.scene import SceneObject, build_scene

FPS = 50
METHOD = "lessmimic-mink"


@dataclass(frozen=True)
class ClipResult:
    """One clip's outcome: the robot clip and its metrics, or the error that stopped it."""

    index: int
    source: str
    robot: RobotClip | None
    metrics: dict
    scale: dict
    error: str | None = None


def _link_map(clip: HumanClip, mapping) -> dict[str, str]:
    from retarget.metrics import DEFAULT_LINK_MAP

    names = set(clip.skeleton.joint_names)
    return {
        **{j: b for j, b in DEFAULT_LINK_MAP.items() if j in names},
        **{link.joint: link.body for link in mapping.links},
    }


def retarget_clip(
    clip: HumanClip, *, height_override: float | None = None, mapping_name: str | None = None
) -> tuple[RobotClip, dict, dict]:
    """(robot clip, metrics, scale summary) for one human clip."""
    from retarget.contact import link_contact_flags
    from retarget.ik import G1Retargeter
    from retarget.mapping import load_mapping
    from retarget.metrics import retarget_metrics
    from retarget.objects import map_objects
    from retarget.scaling import compute_scale, human_to_targets

    if clip.frames < 2:
        raise InputError(clip.source, "frames", f"a clip needs at least 2 frames, got {clip.frames}")
    t0 = time.perf_counter()
    human = clip.resampled(FPS)
    mapping = load_mapping(human.skeleton, mapping_name, source=human.source)
    info = compute_scale(human, mapping, height_override=height_override)
    targets = human_to_targets(human, mapping, height_override=height_override, scale=info)
    objects = map_objects(human, info, targets)
    link_map = _link_map(human, mapping)
    links, contacts = link_contact_flags(human, link_map)
    targets = replace(targets, contact_links=links, object_contact=contacts if objects else None)
    scene = build_scene([SceneObject(o.name, o.geometry, o.physics(), pose=tuple(o.pose[0])) for o in objects])
    ik = G1Retargeter(scene)
    qpos = ik.retarget(targets, {o.name: o.pose for o in objects}, source=human.source)
    objects = tuple(replace(o, pose=ik.objects_pose[o.name]) for o in objects)  # moved clear of planted feet
    robot = RobotClip(
        qpos,
        FPS,
        human.source,
        objects=objects,
        contact_links=links,
        contacts=contacts,
        method=METHOD,
        task=human.task,
        provenance={
            "source": human.source,
            "synthetic": human.synthetic,
            "mapping": mapping.name,
            "source_fps": clip.fps,
        },
    )
    seconds = time.perf_counter() - t0
    return robot, retarget_metrics(robot, human, link_map=link_map, seconds_wall=seconds), info.summary()


def _cache_key(clip: HumanClip, index: int) -> str:
    h = hashlib.sha256()
    for a in (clip.joint_pos, *(o.pose for o in clip.objects)):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(f"{clip.source}|{index}|{clip.fps}|{METHOD}".encode())
    return h.hexdigest()[:16]


def _run_one(args: tuple[int, HumanClip, Path, float | None]) -> ClipResult:
    index, clip, work, height_override = args
    cached = work / f"{_cache_key(clip, index)}.pkl"
    if cached.is_file():
        return pickle.loads(cached.read_bytes())
    try:
        robot, metrics, scale = retarget_clip(clip, height_override=height_override)
        result = ClipResult(index, clip.source, robot, metrics, scale)
    except InputError as exc:  # a bad clip is reported; the others go on
        return ClipResult(index, clip.source, None, {}, {}, error=str(exc))
    tmp = cached.with_suffix(".tmp")
    tmp.write_bytes(pickle.dumps(result))
    tmp.replace(cached)
    return result


def retarget_clips(
    clips: list[HumanClip], work: Path, *, jobs: int = 1, height_override: float | None = None
) -> list[ClipResult]:
    """Retarget every clip (in ``jobs`` processes), resuming from the cache in ``work``."""
    work.mkdir(parents=True, exist_ok=True)
    tasks = [(i, c, work, height_override) for i, c in enumerate(clips)]
    bar = tqdm(total=len(tasks), desc="retarget", unit="clip")
    results: list[ClipResult] = []
    if jobs <= 1:
        for t in tasks:
            results.append(_run_one(t))
            bar.update()
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for r in pool.map(_run_one, tasks):
                results.append(r)
                bar.update()
    bar.close()
    return sorted(results, key=lambda r: r.index)


CARD_NOTES = [
    "`observation.state` is the G1 `qpos` (36): root position, root quaternion wxyz, 29 joint angles in mjlab's "
    "joint order (names in `meta/info.json`); `observation.qvel` (35) its finite differences.",
    "`contact` labels, per robot link, the frames where the human touches an object (a human joint within 2 cm of the "
    "object surface) with a joint mapped to that link; the retargeting brings the link to the object surface on those "
    "frames.",
    "`object.<name>.pose` is each object's pose (position, quaternion wxyz) in the robot's world: real size, placement "
    "following the scaled interaction, moved clear of the robot's planted feet where needed.",
    "`source_frame` is the index of the nearest frame of the source take (at the take's own frame rate).",
    "Per-clip quality figures (penetration, floating, foot sliding, contact preservation, joint limits and speed) "
    "are in `report.json` next to the dataset; kinematic only: physical validity is measured by the physicalize "
    "stage.",
]


def _feature_frames(features) -> dict[str, str]:
    frames = {
        "observation.state": "world, z-up (root); joint space",
        "observation.qvel": "world (root linear), root body (angular)",
        "contact": "per link",
        "source_frame": "source take",
    }
    return {f.name: frames.get(f.name, "world, z-up" if f.name.endswith(".pose") else "") for f in features}


def input_fingerprint(
    input_path: str | None, *, body_model: str | None = None, height_override: float | None = None
) -> str:
    """What a run's output depends on (:mod:`pipeline.stage.state`): every input file's path, size and
    mtime (the embedded default: its generator's source code), the body model's, and the height
    override; not ``jobs``, which changes only the speed."""
    from pipeline import default_input, synthetic
    from pipeline.stage.state import files_fingerprint, fingerprint

    if input_path is None:
        generator = [Path(default_input.__file__), *sorted(Path(synthetic.__file__).parent.glob("*.py"))]
        source = "embedded default " + files_fingerprint(generator, by_content=True)
    else:
        source = files_fingerprint([input_path])
    body = files_fingerprint([body_model]) if body_model else None
    return fingerprint(
        stage="retargeted", method=METHOD, fps=FPS, input=source, body_model=body, height=height_override
    )


def run_stage(
    input_path: str | None,
    name: str,
    *,
    overwrite: bool = False,
    jobs: int = 1,
    body_model: str | None = None,
    height_override: float | None = None,
) -> dict:
    """``lessmimic retarget``: ingest, retarget every clip, write the dataset, report and logs. Without
    ``overwrite``, an existing dataset whose report records this run's :func:`input_fingerprint` is up
    to date: its report comes back with ``"up_to_date": True`` and nothing is done."""
    from pipeline.dataset.card import DatasetCard
    from pipeline.dataset.clips import robot_clips_to_episodes
    from pipeline.dataset.write import check_target, write_dataset
    from pipeline.ingest import ingest
    from pipeline.stage.atomic import write_json_atomic
    from pipeline.stage.inspect_log import write_robot_log
    from pipeline.stage.paths import file_stem, stage_dir
    from pipeline.stage.state import KEY, up_to_date
    from retarget.metrics import summarise
    from retarget.plot import plot_clip

    out = stage_dir(name, "retargeted")
    fp = input_fingerprint(input_path, body_model=body_model, height_override=height_override)
    recorded = None if overwrite or not out.is_dir() else up_to_date(out / "report.json", fp)
    if recorded is not None:
        return {**recorded, "up_to_date": True}
    check_target(out, overwrite)
    t0 = time.perf_counter()
    work = out.parent / ".work" / "retarget"
    if overwrite:  # a fresh run; without --overwrite an interrupted run resumes from `work`
        shutil.rmtree(work, ignore_errors=True)
    human = ingest(input_path, name, overwrite=True, body_model=body_model)
    results = retarget_clips(list(human.clips), work, jobs=jobs, height_override=height_override)
    done = [r for r in results if r.robot is not None]
    failed = [{"episode": r.index, "source": r.source, "error": r.error} for r in results if r.robot is None]
    for r in failed:
        print(f"error: {r['error']}")
    report = {
        "stage": "retargeted",
        "method": METHOD,
        "fps": FPS,
        "input": input_path or "embedded synthetic default",
        "clips": [{"source": r.source, "task": r.robot.task, **r.metrics, "scale": r.scale} for r in done],
        "failed": failed,
        "summary": summarise([r.metrics for r in done]) if done else {},
        KEY: fp,
    }
    if done:
        synthetic = any(r.robot.provenance.get("synthetic") for r in done)
        features, episodes = robot_clips_to_episodes([r.robot for r in done])
        card = DatasetCard(
            title=f"{name}: G1 retargeted motion",
            description=("SYNTHETIC human-object demonstrations, " if synthetic else "Human(-object) motion capture, ")
            + "retargeted to the Unitree G1 by interaction-preserving mink IK (kinematic: not yet physically "
            "simulated).",
            provenance=[r.source for r in done],
            fps=FPS,
            synthetic=synthetic,
            stage="retargeted",
            license="apache-2.0" if synthetic else "other",
            feature_frames=_feature_frames(features),
            notes=CARD_NOTES,
        )
        write_dataset(out, f"lessmimic/{name}-retargeted", FPS, features, episodes, card=card, overwrite=overwrite)
        logs = out.parent / "logs" / "retargeted"
        for k, r in enumerate(tqdm(done, desc="logs and plots", unit="clip")):
            stem = f"{k:03d}_{file_stem(r.source)}"
            write_robot_log(r.robot, logs / f"{stem}.mcap")
            plot_clip(r.robot, human.clips[r.index].resampled(FPS), logs / f"{stem}.png")
        write_json_atomic(
            out / "report.json", {**report, "seconds_wall": time.perf_counter() - t0}
        )  # last: its fingerprint marks a finished run
        shutil.rmtree(work, ignore_errors=True)  # finished: the resume cache has served its purpose
    return report
