"""The features stage: ``datasets/<NAME>/physicalized/`` -> ``datasets/<NAME>/features/`` (LeRobot) +
``report.json``, and per clip a PNG of the DF signals in ``logs/features/``.

The output keeps every column of the physicalized dataset (state, simulated qvel, actions,
torques, object poses and velocities, contacts, validation figures) and adds, per frame, the
interaction features of :mod:`features.compute`: ``observation.df`` (the paper's u_t per link, K x 10),
``observation.df_relative`` (v relative to the object's closest surface point), ``observation.df_demo``
(the released demo's 7 x 4 layout), ``observation.df_object`` (nearest object per link, with several
objects), ``observation.root_command`` (12) and ``observation.proprio`` (93). The task label is the
episode's LeRobot task. The dataset is written atomically; the stage takes seconds per clip. A rerun on
the same physicalized dataset with the same config is up to date and does nothing (:mod:`pipeline.stage.state`).
"""

from __future__ import annotations

import time
from dataclasses import asdict

import numpy as np
from tqdm import tqdm

from features.compute import ClipFeatures, FeatureConfig, FieldCache, clip_features
from pipeline.clip import PhysicalizedClip
from pipeline.dataset.schema import Feature
from pipeline.errors import InputError
from pipeline.robot import g1_model
from pipeline.terms.interaction import DEMO_PARTS, DF_PARTS, feature_names
from pipeline.terms.link_motion import body_ids
from pipeline.terms.observations import PROPRIO_NAMES, ROOT_COMMAND_NAMES

CARD_NOTES = [
    "DF features follow LessMimic Sec. III-A: per link, phi = unsigned distance from the link's body origin to the "
    "nearest object surface (exact: analytic primitives, warp closest point or a cached adaptive octree for meshes), "
    "grad = unit direction from the closest surface point (the outward normal on and inside the surface), v_norm = "
    "(v . grad) grad and v_tan = v - v_norm with v the link's linear velocity from the simulated state (MuJoCo "
    "kinematics, not finite differences).",
    "The interaction window I_t is not stored: load it with LeRobot's `delta_timestamps`, e.g. "
    "`{'observation.df': [-0.08, -0.06, -0.04, -0.02, 0.0]}` for l = 5 at 50 fps (frames before the episode start are "
    "padded and flagged `*_is_pad`), or with `pipeline.dataset.read.WindowDataset(root, keys, history=5)`.",
    "`observation.df_demo` is the input contract of the released LessMimic web demo: for its 7 query bodies, "
    "min(phi, 1 m) and grad in the body's own frame.",
]


def _features(cfg: FeatureConfig, objects: list[str]) -> list[Feature]:
    out = [
        Feature(
            "observation.df",
            "float32",
            feature_names(cfg.links, DF_PARTS),
            "u_t per link: phi, grad phi, v_norm, v_tan",
            "m, 1, m/s",
        ),
        Feature(
            "observation.df_relative",
            "float32",
            feature_names(cfg.links, DF_PARTS),
            "u_t per link with v relative to the velocity of the object's closest surface point",
            "m, 1, m/s",
        ),
        Feature(
            "observation.df_demo",
            "float32",
            feature_names(cfg.demo_links, DEMO_PARTS),
            f"released-demo layout per query body: min(phi, {cfg.demo_max_distance_m:g} m), grad phi in the body frame",
            "m, 1",
        ),
        Feature(
            "observation.root_command",
            "float32",
            ROOT_COMMAND_NAMES,
            f"sparse root target {cfg.root_horizon_s:g} s ahead: position delta, 6-D rotation, target velocity",
            "m, 1, m/s",
        ),
        Feature(
            "observation.proprio",
            "float32",
            PROPRIO_NAMES,
            "joint angles, joint velocities, gravity and angular velocity in the root frame, previous action",
            "rad, rad/s, 1, rad/s, rad",
        ),
    ]
    if len(objects) > 1:
        out.append(
            Feature("observation.df_object", "int64", cfg.links, f"index of the nearest object per link, in {objects}")
        )
    return out


_FRAMES = {
    "observation.df": "world, z-up",
    "observation.df_relative": "world, z-up",
    "observation.df_demo": "query body frame (grad)",
    "observation.root_command": "root heading frame at t (yaw only)",
    "observation.proprio": "joint space; root frame (gravity, angular velocity)",
}


def _data(f: ClipFeatures, several: bool) -> dict[str, np.ndarray]:
    T = len(f.df)
    data = {
        "observation.df": f.df.reshape(T, -1),
        "observation.df_relative": f.df_relative.reshape(T, -1),
        "observation.df_demo": f.df_demo.reshape(T, -1),
        "observation.root_command": f.root_command,
        "observation.proprio": f.proprio,
    }
    if several:
        data["observation.df_object"] = f.object_index
    return data


def _any_contact(clip: PhysicalizedClip) -> np.ndarray | None:
    c = [o.contact for o in clip.robot.objects if o.contact is not None]
    if clip.robot.contacts is not None:
        c.append(clip.robot.contacts.any(1))
    return np.any(c, axis=0) if c else None


def run_stage(name: str, *, overwrite: bool = False, config: FeatureConfig | None = None) -> dict:
    """``lessmimic features``: compute the features of every physicalized clip, write the dataset, report and plots."""
    from features.plot import plot_df
    from pipeline.dataset.card import DatasetCard
    from pipeline.dataset.clips import episodes_to_physicalized_clips, physicalized_clips_to_episodes
    from pipeline.dataset.read import read_card
    from pipeline.dataset.write import check_target, write_dataset
    from pipeline.stage.atomic import write_json_atomic
    from pipeline.stage.paths import file_stem, stage_dir
    from pipeline.stage.state import KEY, dataset_fingerprint, fingerprint, up_to_date

    cfg = config or FeatureConfig()
    body_ids(g1_model(), cfg.query_links, "--links")  # an unknown link fails before any work
    src, out = stage_dir(name, "physicalized"), stage_dir(name, "features")
    if not (src / "meta" / "info.json").is_file():
        ran = src.parent / "logs" / "physicalized" / "report.json"
        if not ran.is_file():
            raise InputError(
                src, "meta/info.json", "no physicalized dataset here: run `lessmimic physicalize --name NAME` first"
            )
        # The physicalize stage ran and kept no clip (none valid): a measured outcome, not an error.
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
    fp, logs = (
        fingerprint(stage="features", physicalized=dataset_fingerprint(src), config=asdict(cfg)),
        out.parent / "logs" / "features",
    )
    recorded = None if overwrite or not out.is_dir() else up_to_date(logs / "report.json", fp)
    if recorded is not None:
        return {**recorded, "up_to_date": True}
    check_target(out, overwrite)
    clips = episodes_to_physicalized_clips(src)
    names = [o.name for o in clips[0].robot.objects]
    if not names:
        raise InputError(
            src, "objects", "the dataset has no object tracks: distance-field features need at least one object"
        )
    t0 = time.perf_counter()
    cache, per_clip, extra, setup = FieldCache(), [], [], 0.0
    for clip in tqdm(clips, desc="features", unit="clip"):
        c0 = time.process_time()
        cache.fields(clip)  # loading meshes and warp, once per object geometry: reported apart from the per-frame work
        setup += time.process_time() - c0
        c0 = time.process_time()
        f = clip_features(clip, cfg, cache)
        cpu = max(time.process_time() - c0, 1e-9)
        extra.append(f)
        per_clip.append(
            {
                "source": clip.robot.source,
                "task": clip.robot.task,
                "frames": clip.frames,
                "cpu_s": cpu,
                "frames_per_cpu_s": clip.frames / cpu,
                "link_queries_per_cpu_s": clip.frames * len(cfg.query_links) / cpu,
                "phi_min_m": float(f.df[..., 0].min()),
                "valid": bool(clip.validation.get("valid", False)),
            }
        )
    features, episodes = physicalized_clips_to_episodes(clips)
    features += _features(cfg, names)
    for ep, f in zip(episodes, extra):
        ep.data.update(_data(f, len(names) > 1))
        ep.meta.update({"stage": "features", "features": asdict(cfg)})
    frames = sum(c["frames"] for c in per_clip)
    cpu = sum(c["cpu_s"] for c in per_clip)
    report = {
        "stage": "features",
        "config": asdict(cfg),
        "clips": per_clip,
        KEY: fp,
        "summary": {
            "clips": len(clips),
            "frames": frames,
            "cpu_s": cpu,
            "frames_per_cpu_s": frames / max(cpu, 1e-9),
            "fields_setup_cpu_s": setup,
        },
    }
    prev = read_card(src)
    synthetic = any(c.robot.provenance.get("synthetic") for c in clips)
    card = DatasetCard(
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
        notes=(prev.notes if prev else []) + CARD_NOTES,
    )
    write_dataset(
        out,
        f"lessmimic/{name}-features",
        int(round(clips[0].robot.fps)),
        features,
        episodes,
        card=card,
        overwrite=overwrite,
    )
    for k, (clip, f) in enumerate(zip(clips, extra)):
        title = f"{clip.robot.source} ({clip.robot.task or 'no task'}): DF over {len(cfg.links)} links"
        plot_df(
            f.df, _any_contact(clip), clip.robot.fps, title[:150], logs / f"{k:03d}_{file_stem(clip.robot.source)}.png"
        )
    report["seconds_wall"] = time.perf_counter() - t0
    write_json_atomic(out / "report.json", report)
    write_json_atomic(logs / "report.json", report)  # last: its fingerprint marks a finished run
    return report
