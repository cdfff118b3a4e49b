"""Commands on one file or one dataset (``inspect``, ``evaluate-retarget``, ``load``, ``verify``, ``publish``,
``merge``), kept apart from the per-stage commands of :mod:`lessmimic.cli`."""

from __future__ import annotations

import argparse
from pathlib import Path


def out_path(path: str) -> Path:
    """``--out``'s path, its folder there already: a command makes no folder above the file (or folder) it is
    told to write, so a mistyped path is an error, not a new tree (``/nonexistent/x.mcap`` made ``/nonexistent``)."""
    from pipeline.errors import InputError

    out = Path(path)
    if not out.parent.is_dir():
        raise InputError(out, "--out", f"its folder {out.parent} does not exist (make it first)")
    return out


def add_joint_names(p: argparse.ArgumentParser) -> None:
    """``--joint-names`` (import, inspect --robot, evaluate-retarget): what the readers' errors ask for
    (:data:`pipeline.readers.npz_order.PASS_NAMES`), read by :func:`pipeline.readers.npz_order.joint_names_option`."""
    p.add_argument(
        "--joint-names",
        default=None,
        metavar="ORDER",
        help="the joint_pos column order of a .npz motion that names none of its joints, where its bodies' kinematics "
        "cannot tell it: mjlab, isaaclab (BeyondMimic's), or the 29 G1 joint names as a comma list or a file of them",
    )


def _joint_names(a: argparse.Namespace):
    from pipeline.readers.npz_order import joint_names_option

    return joint_names_option(a.joint_names) if a.joint_names is not None else None


def _cmd_inspect(a: argparse.Namespace) -> int:
    from pipeline.errors import InputError
    from pipeline.readers import read_clips, read_robot_clip
    from pipeline.stage.inspect_log import write_human_log, write_robot_log

    src = Path(a.file)
    out = out_path(a.out)
    if a.joint_names is not None and not a.robot:
        raise InputError(src, "--joint-names", "applies to a G1 motion (--robot), not a human clip")
    if a.robot:
        from pipeline.geometry import MeshGeometry

        geometry = MeshGeometry(a.object_mesh) if a.object_mesh else None
        print(write_robot_log(read_robot_clip(src, object_geometry=geometry, joint_names=_joint_names(a)), out))
        return 0
    clips = read_clips(src, body_model=a.body_model, fps=a.fps, units=a.units, mesh=a.object_mesh)
    for i, c in enumerate(clips):
        print(write_human_log(c, out if len(clips) == 1 else out.with_name(f"{out.stem}_{i:03d}.mcap")))
    return 0


def _cmd_evaluate_retarget(a: argparse.Namespace) -> int:
    import json

    from pipeline.stage.atomic import write_json_atomic
    from retarget.metrics import evaluate_file

    out = out_path(a.out) if a.out else None
    metrics = evaluate_file(a.file, human_path=a.human, object_mesh=a.object_mesh, joint_names=_joint_names(a))
    text = json.dumps({"file": str(a.file), **metrics}, indent=2, default=float)
    if out is not None:
        write_json_atomic(out, json.loads(text))
    print(text)
    return 0


def _cmd_load(a: argparse.Namespace) -> int:
    from pipeline.dataset.hub import load

    ds = load(a.dataset)
    print(f"{ds.repo_id}: {ds.num_episodes} episodes, {ds.num_frames} frames at {ds.fps} fps")
    for k, v in ds.features.items():
        print(f"  {k}: {v['dtype']} {tuple(v['shape'])}")
    return 0


def _cmd_verify(a: argparse.Namespace) -> int:
    from pipeline.dataset.verify import dataset_folders, verify_dataset

    for root in dataset_folders(a.dataset):
        r = verify_dataset(root)
        made = f", made from {r['upstream']}/ as it is" if r["upstream"] else ""
        print(f"{r['dataset']}: ok: {r['files']} files ({r['bytes']} bytes) match their sha256; "
              f"{r['episodes']} episodes, {r['frames']} frames within range{made}")  # fmt: skip
    return 0


def _cmd_publish(a: argparse.Namespace) -> int:
    from pipeline.dataset.hub import publish

    print(publish(Path(a.dataset), a.repo_id, private=a.private))
    return 0


def merge_lock_folder(out: Path) -> Path:
    """The folder whose writer lock a merge into ``out`` holds: ``datasets/<NAME>/`` when ``out`` lies in one (the
    lock every writer of NAME holds: :mod:`pipeline.stage.lock`), else the folder holding ``out``."""
    from pipeline.stage.paths import datasets_root

    root, target = datasets_root().resolve(), out.resolve()
    parts = target.relative_to(root).parts if target.is_relative_to(root) else ()
    return root / parts[0] if len(parts) >= 2 else target.parent


def _cmd_merge(a: argparse.Namespace) -> int:
    from pipeline.dataset.merge import merge_datasets
    from pipeline.stage.lock import dataset_lock

    out = out_path(a.out)
    with dataset_lock(merge_lock_folder(out)):  # one writer per dataset, as every writing command
        print(merge_datasets([Path(r) for r in a.shards], out, a.repo_id, overwrite=a.overwrite))
    return 0


def add_tools(sub) -> None:
    p = sub.add_parser("inspect", help="write an MCAP inspection log (Foxglove) for a clip file")
    p.add_argument("file")
    p.add_argument("--out", required=True, help="output .mcap path")
    p.add_argument("--robot", action="store_true", help="the file is a G1 motion (BeyondMimic .npz or GMR .pkl)")
    p.add_argument(
        "--object-mesh",
        default=None,
        help="mesh of the object the file carries poses for (a human OMOMO .pt: default <object>.obj beside it)",
    )
    p.add_argument("--body-model", default=None)
    p.add_argument("--fps", type=float, default=None, help="frame rate of a file that carries none (as retarget's)")
    p.add_argument("--units", default=None, choices=("auto", "m", "cm", "mm", "inch"), help="as retarget's --units")
    add_joint_names(p)
    p.set_defaults(func=_cmd_inspect)
    p = sub.add_parser(
        "evaluate-retarget",
        help="retarget quality metrics of a G1 motion file (ours or a peer's) with our collision model",
    )
    p.add_argument("file", help="BeyondMimic/OmniRetarget .npz or GMR .pkl")
    p.add_argument("--human", default=None, help="the human clip it came from (foot contacts, contact flags)")
    p.add_argument("--object-mesh", default=None, help="mesh of the object the file carries poses for")
    p.add_argument("--out", default=None, help="also write the metrics to this JSON file")
    add_joint_names(p)
    p.set_defaults(func=_cmd_evaluate_retarget)
    p = sub.add_parser("load", help="load a dataset by path or hub repo id with LeRobot's loader and summarise it")
    p.add_argument("dataset")
    p.set_defaults(func=_cmd_load)
    p = sub.add_parser(
        "verify",
        help="check a dataset: every file against its sha256, its chain, info.json against the data, every value in "
        "its column's range",
    )
    p.add_argument("dataset", help="a dataset folder, datasets/<NAME>/ (every stage), a dataset NAME, or a hub repo id")
    p.set_defaults(func=_cmd_verify)
    p = sub.add_parser("publish", help="push a dataset folder to the Hugging Face hub")
    p.add_argument("dataset")
    p.add_argument("--repo-id", required=True)
    p.add_argument("--private", action="store_true")
    p.set_defaults(func=_cmd_publish)
    p = sub.add_parser("merge", help="merge dataset shards into one dataset")
    p.add_argument("shards", nargs="+")
    p.add_argument("--out", required=True)
    p.add_argument("--repo-id", required=True)
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=_cmd_merge)
