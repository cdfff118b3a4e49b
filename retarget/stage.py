"""The retarget stage: every human clip of the input -> a G1 :class:`RobotClip` (:func:`retarget.clip.retarget_clip`),
written as ``datasets/<NAME>/retargeted/`` (LeRobot) with ``report.json``, and per clip an MCAP log and a PNG plot
(:mod:`retarget.plot`) in ``datasets/<NAME>/logs/retargeted/``.

With ``variants`` (:mod:`retarget.augment`) every clip is retargeted once per variant of its object (the ``x1``
variant is the clip itself); a variant that cannot be made of a clip (no object; a cylinder of a chair) is listed in
the report's ``not_applicable`` with its reason, and the report's ``variants`` holds the retarget figures per variant.

The clips are independent: they run in worker processes or on Ray (``jobs``, ``executor``), each kept as it
finishes so an interrupted run resumes (:mod:`pipeline.stage.run`); a failing clip is reported with its one-line
error and the others go on. A rerun on the same input with the same options finds the dataset up to date
(:func:`input_fingerprint`) and does nothing.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial

from tqdm import tqdm

from pipeline.clip import HumanClip, RobotClip
from pipeline.dataset.card import DatasetCard
from pipeline.dataset.clips import robot_clips_to_episodes
from pipeline.dataset.objects import objects_note
from pipeline.dataset.write import write_dataset
from pipeline.errors import InputError
from pipeline.stage.executor import check_executor
from pipeline.stage.inspect_log import write_robot_log
from pipeline.stage.paths import file_stem, stage_dir
from pipeline.stage.run import StageRun, digest
from pipeline.stage.state import files_fingerprint, fingerprint
from pipeline.suspicious import collecting
from retarget.augment import Variant
from retarget.augment import not_applicable as augment_not_applicable
from retarget.clip import FPS, METHOD, retarget_clip
from retarget.metrics import summarise
from retarget.plot import plot_clip


@dataclass(frozen=True)
class ClipResult:
    """One clip's outcome: the robot clip and its metrics, or the error that stopped it."""

    index: int
    source: str
    robot: RobotClip | None
    metrics: dict
    scale: dict
    error: str | None = None
    variant: str | None = None


Item = tuple[int, HumanClip, Variant | None]


def retarget_one(item: Item, height_override: float | None = None) -> ClipResult:
    """:func:`retarget_clip` of the ``(index, clip, variant)`` item; a bad clip's :class:`InputError` becomes its
    result."""
    index, clip, variant = item
    label = None if variant is None else variant.label
    try:
        robot, metrics, scale = retarget_clip(clip, height_override=height_override, variant=variant)
    except InputError as exc:  # a bad clip is reported; the others go on
        return ClipResult(index, clip.source, None, {}, {}, error=str(exc), variant=label)
    return ClipResult(index, robot.source, robot, metrics, scale, variant=label)


def _clip_key(k: int, item: Item) -> str:
    clip, variant = item[1], item[2]
    label = None if variant is None else variant.label
    return digest(k, clip.source, label, clip.fps, clip.joint_pos, *(o.pose for o in clip.objects))


def work_items(clips: Sequence[HumanClip], variants: Sequence[Variant]) -> tuple[list[Item], list[dict]]:
    """The stage's items: every clip, once per variant (none: once as it is), and the variants that cannot be made
    of a clip, each ``{"episode", "source", "variant", "reason"}``."""
    items, skipped = [], []
    for index, clip in enumerate(clips):
        for v in variants or (None,):
            why = None if v is None else augment_not_applicable(clip.objects[0].geometry if clip.objects else None, v)
            if why is None:
                items.append((index, clip, v))
            else:
                skipped.append({"episode": index, "source": clip.source, "variant": v.label, "reason": why})
    return items, skipped


CARD_NOTES = [
    "`observation.state` is the G1 `qpos` (36): root position, root quaternion wxyz, 29 joint angles in mjlab's "
    "joint order (names in `meta/info.json`); `observation.qvel` (35) its finite differences.",
    "`contact` labels, per robot link, the frames where the human touches an object (a human joint within 2 cm of the "
    "object surface) with a joint mapped to that link; the retargeting brings the link to the object surface on those "
    "frames.",
    "`object.pose` is the clip's object's pose (position, quaternion wxyz) in the robot's world: real size, placement "
    "following the scaled interaction, moved clear of the robot's planted feet where needed.",
    "`source_frame` is the index of the nearest frame of the source take (at the take's own frame rate).",
    "Per-clip quality figures (penetration, floating, foot sliding, contact preservation, joint limits and speed) "
    "are in `report.json` next to the dataset; kinematic only: physical validity is measured by the physicalize "
    "stage.",
]


def feature_frames(features) -> dict[str, str]:
    frames = {
        "observation.state": "world, z-up (root); joint space",
        "observation.qvel": "world (root linear), root body (angular)",
        "contact": "per link",
        "source_frame": "source take",
    }
    return {f.name: frames.get(f.name, "world, z-up" if f.name.endswith(".pose") else "") for f in features}


def input_fingerprint(
    source: str,
    *,
    body_model: str | None = None,
    height_override: float | None = None,
    variants: Sequence[Variant] = (),
) -> str:
    """What a run's output depends on (:mod:`pipeline.stage.state`): the human input's ``source`` fingerprint
    (:func:`ingest.stage.source_fingerprint`), the body model's, the height override and the variants; not ``jobs``,
    which changes only the speed."""
    body = files_fingerprint([body_model]) if body_model else None
    labels = [v.label for v in variants] or None
    return fingerprint(
        stage="retargeted",
        method=METHOD,
        fps=FPS,
        input=source,
        body_model=body,
        height=height_override,
        **({"variants": labels} if labels else {}),
    )


def _card(name: str, done: list[ClipResult], features) -> DatasetCard:
    synthetic_ = any(r.robot.provenance.get("synthetic") for r in done)
    return DatasetCard(
        title=f"{name}: G1 retargeted motion",
        description=("SYNTHETIC human-object demonstrations, " if synthetic_ else "Human(-object) motion capture, ")
        + "retargeted to the Unitree G1 by interaction-preserving mink IK (kinematic: not yet physically simulated).",
        provenance=[r.source for r in done],
        fps=FPS,
        synthetic=synthetic_,
        stage="retargeted",
        license="apache-2.0" if synthetic_ else "other",
        feature_frames=feature_frames(features),
        notes=[*CARD_NOTES, objects_note([r.robot for r in done])],
    )


def run_stage(
    name: str,
    source: str,
    human: Callable[[], Sequence[HumanClip]],
    *,
    input_label: str,
    overwrite: bool = False,
    jobs: int = 1,
    executor: str = "local",
    body_model: str | None = None,
    height_override: float | None = None,
    variants: Sequence[Variant] = (),
) -> dict:
    """``lessmimic retarget``: retarget every clip of ``human()`` (once per variant of ``variants``; the human stage,
    run only when there is work: the CLI passes :func:`ingest.stage.ingest`), write the dataset, report and logs.
    ``source`` fingerprints the input (:func:`ingest.stage.source_fingerprint`), ``input_label`` names it in the
    report. Without ``overwrite``, a finished run on the same input with the same options (:func:`input_fingerprint`)
    is up to date: its report comes back with ``"up_to_date": True`` and nothing is done. The run's resume record is
    written only after ``human()`` has read and validated the input, so a refused input leaves nothing behind."""
    check_executor(executor, jobs)
    run = StageRun(
        stage_dir(name, "retargeted"),
        input_fingerprint(source, body_model=body_model, height_override=height_override, variants=variants),
    )
    if not overwrite and (done := run.finished()) is not None:
        return {**done, "up_to_date": True}
    run.check(overwrite)
    t0 = time.perf_counter()
    with collecting() as suspicious:  # what the input has that is only suspicious: in the report (pipeline.suspicious)
        clips = list(human())
    run.begin(overwrite)
    retarget = partial(retarget_one, height_override=height_override)
    items, skipped = work_items(clips, variants)
    results = run.map(retarget, items, key=_clip_key, jobs=jobs, executor=executor, desc="retarget")
    done = [r for r in results if r.robot is not None]
    failed = [
        {"episode": r.index, "source": r.source, **({"variant": r.variant} if r.variant else {}), "error": r.error}
        for r in results
        if r.robot is None
    ]
    for r in failed:
        print(f"error: {r['error']}")
    report = {
        "stage": "retargeted",
        "method": METHOD,
        "fps": FPS,
        "input": input_label,
        "clips": [
            {"source": r.source, "task": r.robot.task, **({"variant": r.variant} if r.variant else {}), **r.metrics}
            | {"scale": r.scale}
            for r in done
        ],
        "failed": failed,
        "summary": summarise([r.metrics for r in done]) if done else {},
        "warnings": suspicious,
    }
    if variants:
        report["variants"] = {
            v.label: summarise(m) for v in variants if (m := [r.metrics for r in done if r.variant == v.label])
        }
        report["not_applicable"] = skipped
    if not done:  # nothing to write: not a finished run (a rerun tries again)
        return report
    features, episodes = robot_clips_to_episodes([r.robot for r in done])
    write_dataset(
        run.out,
        f"lessmimic/{name}-retargeted",
        FPS,
        features,
        episodes,
        card=_card(name, done, features),
        overwrite=run.replaces,
    )
    for k, r in enumerate(tqdm(done, desc="logs and plots", unit="clip")):
        stem = f"{k:03d}_{file_stem(r.source)}"
        write_robot_log(r.robot, run.logs / f"{stem}.mcap")
        plot_clip(r.robot, clips[r.index].resampled(FPS), run.logs / f"{stem}.png")
    return run.finish({**report, "seconds_wall": time.perf_counter() - t0}, dataset_written=True)
