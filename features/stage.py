"""The features stage: ``datasets/<NAME>/physicalized/`` -> ``datasets/<NAME>/features/`` (LeRobot) +
``report.json``, and per clip a PNG of the DF signals in ``logs/features/``.

The output keeps every column of the physicalized dataset (state, simulated qvel, actions,
torques, object poses and velocities, contacts, validation figures) and adds, per frame, the
interaction features of :mod:`features.compute`: ``observation.df`` (the paper's u_t per link, K x 10),
``observation.df_relative`` (v relative to the object's closest surface point), ``observation.df_demo``
(the released demo's 7 x 4 layout), ``observation.df_object`` (nearest object per link, with several
objects), ``observation.root_command`` (12) and ``observation.proprio`` (93). The task label is the
episode's LeRobot task. The dataset is written atomically; the stage takes seconds per clip. The clips run
in worker processes or on Ray (``jobs``, ``executor``) and an interrupted run resumes (:mod:`pipeline.stage.run`);
a rerun on the same physicalized dataset with the same config is up to date and does nothing.
"""

from __future__ import annotations

import time
from dataclasses import asdict
from functools import partial
from pathlib import Path

import numpy as np

from features.compute import ClipFeatures, FeatureConfig, FieldCache, clip_features
from features.plot import plot_df
from pipeline.clip import PhysicalizedClip
from pipeline.dataset.card import DatasetCard
from pipeline.dataset.clips import episodes_to_physicalized_clips, physicalized_clips_to_episodes
from pipeline.dataset.objects import objects_note
from pipeline.dataset.read import read_card, read_info
from pipeline.dataset.schema import Feature
from pipeline.dataset.write import write_dataset
from pipeline.errors import InputError
from pipeline.robot import g1_model
from pipeline.stage.executor import check_executor
from pipeline.stage.paths import file_stem, logs_dir, stage_dir
from pipeline.stage.run import StageRun, digest
from pipeline.stage.state import dataset_fingerprint, fingerprint
from pipeline.terms.layout import (
    CONTROL_FPS,
    DEMO_MAX_DISTANCE_M,
    DEMO_PARTS,
    DF,
    DF_DEMO,
    DF_OBJECT,
    DF_PARTS,
    DF_RELATIVE,
    HISTORY,
    PROPRIO,
    PROPRIO_NAMES,
    ROOT_COMMAND,
    ROOT_COMMAND_NAMES,
    feature_names,
)
from pipeline.terms.link_motion import body_ids

_WINDOW = [-k / CONTROL_FPS + 0.0 for k in range(HISTORY - 1, -1, -1)]  # the window's delta_timestamps
CARD_NOTES = [
    "DF features follow LessMimic Sec. III-A: per link, phi = unsigned distance from the link's body origin to the "
    "nearest object surface (exact: analytic primitives, warp closest point or a cached adaptive octree for meshes), "
    "grad = unit direction from the closest surface point (the outward normal on and inside the surface), v_norm = "
    "(v . grad) grad and v_tan = v - v_norm with v the link's linear velocity from the simulated state (MuJoCo "
    "kinematics, not finite differences).",
    "The interaction window I_t is not stored: load it with LeRobot's `delta_timestamps`, e.g. "
    f"`{{'{DF}': {_WINDOW}}}` for l = {HISTORY} at {CONTROL_FPS} fps (frames before the episode start are "
    f"padded and flagged `*_is_pad`), or with `pipeline.dataset.WindowDataset(root, keys, history={HISTORY})`.",
    f"`{DF_DEMO}` is the input contract of the released LessMimic web demo: for its 7 query bodies, "
    f"min(|phi|, {DEMO_MAX_DISTANCE_M:g} m) and the unsigned field's gradient in the body's own frame, zero beyond "
    f"{DEMO_MAX_DISTANCE_M:g} m (the viewer's unsigned voxel grid).",
]


def _features(cfg: FeatureConfig, objects: list[str]) -> list[Feature]:
    out = [
        Feature(
            DF,
            "float32",
            feature_names(cfg.links, DF_PARTS),
            "u_t per link: phi, grad phi, v_norm, v_tan",
            "m, 1, m/s",
        ),
        Feature(
            DF_RELATIVE,
            "float32",
            feature_names(cfg.links, DF_PARTS),
            "u_t per link with v relative to the velocity of the object's closest surface point",
            "m, 1, m/s",
        ),
        Feature(
            DF_DEMO,
            "float32",
            feature_names(cfg.demo_links, DEMO_PARTS),
            f"released-demo layout per query body: min(|phi|, {cfg.demo_max_distance_m:g} m), the unsigned "
            "field's grad in the body frame, zero beyond",
            "m, 1",
        ),
        Feature(
            ROOT_COMMAND,
            "float32",
            ROOT_COMMAND_NAMES,
            f"sparse root target {cfg.root_horizon_s:g} s ahead: position delta, 6-D rotation, target velocity",
            "m, 1, m/s",
        ),
        Feature(
            PROPRIO,
            "float32",
            PROPRIO_NAMES,
            "joint angles, joint velocities, gravity and angular velocity in the root frame, previous action",
            "rad, rad/s, 1, rad/s, rad",
        ),
    ]
    if len(objects) > 1:
        out.append(Feature(DF_OBJECT, "int64", cfg.links, f"index of the nearest object per link, in {objects}"))
    return out


_FRAMES = {
    DF: "world, z-up",
    DF_RELATIVE: "world, z-up",
    DF_DEMO: "query body frame (grad)",
    ROOT_COMMAND: "root heading frame at t (yaw only)",
    PROPRIO: "joint space; root frame (gravity, angular velocity)",
}


def _data(f: ClipFeatures, several: bool) -> dict[str, np.ndarray]:
    T = len(f.df)
    data = {
        DF: f.df.reshape(T, -1),
        DF_RELATIVE: f.df_relative.reshape(T, -1),
        DF_DEMO: f.df_demo.reshape(T, -1),
        ROOT_COMMAND: f.root_command,
        PROPRIO: f.proprio,
    }
    if several:
        data[DF_OBJECT] = f.object_index
    return data


def _any_contact(clip: PhysicalizedClip) -> np.ndarray | None:
    c = [o.contact for o in clip.robot.objects if o.contact is not None]
    if clip.robot.contacts is not None:
        c.append(clip.robot.contacts.any(1))
    return np.any(c, axis=0) if c else None


_FIELDS = FieldCache()  # per process: an object's field is built once, however many clips use it


def features_one(item: tuple[int, PhysicalizedClip], config: FeatureConfig) -> tuple[ClipFeatures, dict]:
    """The features of the ``(index, clip)`` item and its figures (CPU time of the per-frame work, apart from
    loading the objects' fields: meshes and warp, once per object geometry and process)."""
    _, clip = item
    c0 = time.process_time()
    _FIELDS.fields(clip)
    setup = time.process_time() - c0
    c0 = time.process_time()
    f = clip_features(clip, config, _FIELDS)
    cpu = max(time.process_time() - c0, 1e-9)
    return f, {
        "source": clip.robot.source,
        "task": clip.robot.task,
        "frames": clip.frames,
        "cpu_s": cpu,
        "frames_per_cpu_s": clip.frames / cpu,
        "link_queries_per_cpu_s": clip.frames * len(config.query_links) / cpu,
        "phi_min_m": float(f.df[..., 0].min()),
        "valid": bool(clip.validation.get("valid", False)),
        "fields_setup_cpu_s": setup,
    }


def _clip_key(k: int, item: tuple[int, PhysicalizedClip]) -> str:
    clip = item[1]
    return digest(k, clip.robot.source, clip.robot.qpos, clip.qvel, *(o.pose for o in clip.robot.objects))


def _nothing_to_do(src: Path) -> dict:
    """The physicalize stage ran and kept no clip (none valid): a measured outcome, not an error."""
    ran = logs_dir(src) / "report.json"
    if not ran.is_file():
        why = "no physicalized dataset here: run `lessmimic physicalize --name NAME` first"
        raise InputError(src, "meta/info.json", why)
    why = (
        f"nothing to do: the physicalize stage kept no clip (none valid; see {ran}); "
        "`make physicalize KEEP_INVALID=1 OVERWRITE=1` keeps invalid clips with their validation figures"
    )
    return {
        "stage": "features",
        "skipped": why,
        "clips": [],
        "summary": {"clips": 0, "frames": 0, "frames_per_cpu_s": 0.0},
    }


def _card(name: str, src: Path, clips: list[PhysicalizedClip]) -> DatasetCard:
    prev = read_card(src)
    synthetic = any(c.robot.provenance.get("synthetic") for c in clips)
    return DatasetCard(
        title=f"{name}: G1 interaction features (distance fields)",
        description=("SYNTHETIC demonstrations: " if synthetic else "")
        + "physically simulated G1 state-action data with LessMimic "
        "distance-field interaction features, root commands and proprioception, ready for behaviour cloning.",
        provenance=[c.robot.source for c in clips] + [str(src)],
        fps=int(round(clips[0].robot.fps)),
        synthetic=synthetic,
        stage="features",
        actuator_profile=prev.actuator_profile if prev else "",
        license=prev.license if prev else "other",
        feature_frames={**(prev.feature_frames if prev else {}), **_FRAMES},
        notes=[n for n in (prev.notes if prev else []) if not n.startswith("Objects are columns")]
        + CARD_NOTES
        + [objects_note([c.robot for c in clips])],
    )


def run_stage(
    name: str, *, overwrite: bool = False, config: FeatureConfig | None = None, jobs: int = 1, executor: str = "local"
) -> dict:
    """``lessmimic features``: compute the features of every physicalized clip, write the dataset, report and plots."""
    check_executor(executor, jobs)
    cfg = config or FeatureConfig()
    body_ids(g1_model(), cfg.query_links, "--links")  # an unknown link fails before any work
    src = stage_dir(name, "physicalized")
    if not (src / "meta" / "info.json").is_file():
        return _nothing_to_do(src)
    if not any(k.startswith("object") and k.endswith(".pose") for k in read_info(src)["features"]):  # before work
        why = "the dataset has no object tracks: distance-field features need at least one object"
        raise InputError(src, "objects", why)
    run = StageRun(
        stage_dir(name, "features"),
        fingerprint(stage="features", physicalized=dataset_fingerprint(src), config=asdict(cfg)),
    )
    if not overwrite and (done := run.finished()) is not None:
        return {**done, "up_to_date": True}
    run.begin(overwrite)
    clips = episodes_to_physicalized_clips(src)
    names = [o.name for o in clips[0].robot.objects]
    t0 = time.perf_counter()
    compute = partial(features_one, config=cfg)
    results = run.map(compute, list(enumerate(clips)), key=_clip_key, jobs=jobs, executor=executor, desc="features")
    per_clip = [{k: v for k, v in figures.items() if k != "fields_setup_cpu_s"} for _, figures in results]
    features, episodes = physicalized_clips_to_episodes(clips)
    features += _features(cfg, names)
    for ep, (f, _) in zip(episodes, results):
        ep.data.update(_data(f, len(names) > 1))
        ep.meta.update({"stage": "features", "features": asdict(cfg)})
    frames, cpu = sum(c["frames"] for c in per_clip), sum(c["cpu_s"] for c in per_clip)
    summary = {
        "clips": len(clips),
        "frames": frames,
        "cpu_s": cpu,
        "frames_per_cpu_s": frames / max(cpu, 1e-9),
        "fields_setup_cpu_s": sum(figures["fields_setup_cpu_s"] for _, figures in results),
    }
    fps = int(round(clips[0].robot.fps))
    write_dataset(
        run.out,
        f"lessmimic/{name}-features",
        fps,
        features,
        episodes,
        card=_card(name, src, clips),
        overwrite=run.replaces,
    )
    for k, (clip, (f, _)) in enumerate(zip(clips, results)):
        title = f"{clip.robot.source} ({clip.robot.task or 'no task'}): DF over {len(cfg.links)} links"
        plot_df(
            f.df,
            _any_contact(clip),
            clip.robot.fps,
            title[:150],
            run.logs / f"{k:03d}_{file_stem(clip.robot.source)}.png",
        )
    report = {"stage": "features", "config": asdict(cfg), "clips": per_clip, "summary": summary}
    return run.finish({**report, "seconds_wall": time.perf_counter() - t0}, dataset_written=True)
