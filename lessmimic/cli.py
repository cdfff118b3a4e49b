"""``lessmimic``: one command line entry point, a subcommand per stage and per tool.

Stages read ``--input`` (a mocap file or folder; default: the embedded synthetic
demonstrations) and write ``datasets/<NAME>/<stage>/``, a LeRobot v3.0 dataset root
with a ``report.json``; inspection logs go to ``datasets/<NAME>/logs/<stage>/``.
Bad input stops with one line ``error: <file>: frame <k>: <field>: <problem>`` and exit
status 2, leaving no partial output. A rerun on the same input with the same options finds
its output up to date and does nothing; an interrupted run (killed at any point) resumes where it
stopped (:mod:`pipeline.stage.run`); other input or options over an existing output need ``--overwrite``.
A command that writes into ``datasets/<NAME>/`` holds its lock (:mod:`pipeline.stage.lock`): a second writer
stops in one line naming the first.
"""

from __future__ import annotations

import argparse
import math
import sys

from lessmimic.corpus_commands import add_corpus
from lessmimic.export_commands import add_export_motion
from lessmimic.residual_commands import add_residual
from lessmimic.tool_commands import add_joint_names, add_tools
from lessmimic.train_commands import add_train
from pipeline.errors import INTERRUPTED, SUBJECT_HEIGHT_M, InputError, os_error_line
from pipeline.stage.executor import EXECUTORS
from pipeline.stage.lock import writer_lock
from pipeline.stage.outputs import mujoco_log_into, temporary_arrow_cache
from pipeline.stage.state import up_to_date_line
from pipeline.stage.undo import Undo


def _stage_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--input",
        default=None,
        help="mocap file or folder (BVH, OMOMO .pt, AMASS .npz, C3D, MCAP, keypoints .npz/.csv), or synthetic:<seeds>"
        "[:<tasks>] (the embedded generator over seeds, e.g. synthetic:0-24); default: embedded synthetic demos",
    )
    p.add_argument(
        "--name", default="default", help="dataset name: outputs go to datasets/<NAME>/<stage>/ (default: default)"
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing output dataset")
    p.add_argument(
        "--body-model", default=None, help="SMPL-H / SMPL-X body model file or folder (needed for AMASS .npz)"
    )


def _run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("-j", "--jobs", type=int, default=1, help="worker processes over clips (default 1)")
    p.add_argument(
        "--executor",
        default="local",
        choices=EXECUTORS,
        help="where the clips run: local worker processes, or a Ray cluster ($RAY_ADDRESS; unset: a local Ray "
        "instance of --jobs CPUs) (default local)",
    )


def _cmd_retarget(a: argparse.Namespace) -> int:
    from lessmimic.chain import retarget
    from retarget.augment import parse_variants

    if a.height is not None and not SUBJECT_HEIGHT_M[0] <= a.height <= SUBJECT_HEIGHT_M[1]:  # before any work
        raise InputError(
            a.height, "--height", "must be the subject's height in metres, within {:g}-{:g}".format(*SUBJECT_HEIGHT_M)
        )
    read = _read_options(a)
    variants = parse_variants(a.augment_scales, a.augment_shapes) if a.augment_scales else ()
    report = retarget(
        a.input,
        a.name,
        overwrite=a.overwrite,
        jobs=a.jobs,
        executor=a.executor,
        body_model=a.body_model,
        height_override=a.height,
        variants=variants,
        read=read,
    )
    if report.get("up_to_date"):
        print(up_to_date_line("retarget", a.name, "retargeted"))
        return 0
    if not report["clips"]:
        print(f"retargeted nothing: every clip failed ({len(report['failed'])}); datasets/{a.name}/ is left as it was")
        return 1
    s = report["summary"]
    print(f"retargeted {len(report['clips'])} clip(s), {len(report['failed'])} failed -> datasets/{a.name}/retargeted/")
    if report.get("not_applicable"):
        print(f"  {len(report['not_applicable'])} variant(s) not applicable (reasons in report.json)")
    if report.get("warnings"):  # each printed once on stderr as it was read
        print(f"  {len(report['warnings'])} warning(s) about the input, read as it is (listed in report.json)")
    for k in (
        "object_penetration_frac_1cm",
        "ground_penetration_frac_1cm",
        "float_frac_2cm",
        "foot_slide_frac_1cm_per_frame",
        "contact_preservation_frac",
        "joint_limit_violation_frac",
        "frames_per_s",
    ):
        if k in s:
            print(f"  {k}: {s[k]:.4g}")
    return 0


def _read_options(a: argparse.Namespace) -> dict:
    """The readers' options of ``retarget`` (``--fps``, ``--units``, ``--object-mesh``), checked before any work: they
    apply to mocap files only, a rate is positive, a mesh readable (:func:`pipeline.collision_mesh.load_mesh`)."""
    read = {"fps": a.fps, "units": a.units, "mesh": a.object_mesh}
    given = [f"--{k.replace('mesh', 'object-mesh')}" for k, v in read.items() if v is not None]
    if given and (a.input is None or a.input.startswith("synthetic:")):
        raise InputError(a.input or "embedded synthetic default", given[0], "applies to mocap files, not this input")
    if a.fps is not None and not (math.isfinite(a.fps) and a.fps > 0):
        raise InputError(a.fps, "--fps", "must be a positive frame rate in Hz")
    if a.object_mesh is not None:
        from pipeline.collision_mesh import load_mesh

        load_mesh(a.object_mesh)
    return read


def _cmd_import(a: argparse.Namespace) -> int:
    from pipeline.readers.npz_order import joint_names_option
    from retarget.imported import run_stage

    if a.input is None:
        raise InputError(None, "--input", "import needs G1 motion files or a folder of them")
    report = run_stage(
        a.input,
        a.name,
        overwrite=a.overwrite,
        jobs=a.jobs,
        executor=a.executor,
        object_mesh=a.object_mesh,
        object_mass=a.object_mass,
        joint_names=joint_names_option(a.joint_names) if a.joint_names is not None else None,
    )
    if report.get("up_to_date"):
        print(up_to_date_line("import", a.name, "retargeted"))
        return 0
    held = sorted({j for c in report["clips"] for j in c["held_joints"]})
    print(
        f"imported {len(report['clips'])} G1 motion(s), {report['summary']['frames']} frames"
        f" -> datasets/{a.name}/retargeted/" + (f" (held at the default pose: {', '.join(held)})" if held else "")
    )
    return 0


def _cmd_physicalize(a: argparse.Namespace) -> int:
    from physicalize.stage import run_stage

    report = run_stage(
        a.name,
        overwrite=a.overwrite,
        teacher=a.teacher,
        profile=a.profile,
        keep_invalid=a.keep_invalid,
        jobs=a.jobs,
        executor=a.executor,
        search_budget=a.search_budget,
    )
    if report.get("up_to_date"):
        print(up_to_date_line("physicalize", a.name, "physicalized"))
        return 0
    s = report["summary"]
    n, kept = len(report["clips"]), s.get("episodes_written", 0)
    where = (
        f"datasets/{a.name}/physicalized/"
        if kept
        else f"nothing written (report: datasets/{a.name}/logs/physicalized/report.json)"
    )
    rejected, failed = s.get("clips_rejected", {}), s.get("clips_failed", {})
    print(
        f"physicalized {n} clip(s): valid_frac {s.get('valid_frac', 0):.3g}, {kept} episode(s) -> {where}"
        + (
            f"; rejected {sum(rejected.values())} ({', '.join(f'{k}: {v}' for k, v in rejected.items())})"
            if rejected
            else ""
        )
        + (f"; failed {sum(failed.values())} ({', '.join(f'{k}: {v}' for k, v in failed.items())})" if failed else "")
    )
    for k in ("mpjpe_m", "root_pos_err_max_m", "penetration_max_m", "foot_slide_frac_1cm_per_frame", "realtime_factor"):
        if k in s:
            print(f"  {k}: {s[k]:.4g}")
    if any(" " in key for key in report.get("yield", {})):  # an augmented corpus: the yield per task and variant
        for key, row in report["yield"].items():
            why = {**row["rejected"], **row["failed"]}
            capped = f", {row['payload_capped']} with the object capped" if row.get("payload_capped") else ""
            print(f"  {key}: {row['valid']}/{row['clips']} valid{capped}" + (f" ({_counts(why)})" if why else ""))
    return 0  # invalid clips are a measured outcome (in the report), not a failure of the run


def _counts(counter: dict) -> str:
    return ", ".join(f"{k}: {v}" for k, v in counter.items())


def _cmd_features(a: argparse.Namespace) -> int:
    from features.compute import FeatureConfig
    from features.stage import run_stage
    from pipeline.dataset.read import read_info
    from pipeline.stage.paths import stage_dir

    if (src := stage_dir(a.name, "physicalized")).is_dir():  # a damaged dataset is named as such, not "nothing to do"
        read_info(src)
    cfg = FeatureConfig(**({"links": tuple(a.links.split(","))} if a.links else {}))
    report = run_stage(a.name, overwrite=a.overwrite, config=cfg, jobs=a.jobs, executor=a.executor)
    if report.get("up_to_date"):
        print(up_to_date_line("features", a.name, "features"))
        return 0
    if "skipped" in report:
        print(f"features: {report['skipped']}")
        return 0
    s = report["summary"]
    print(
        f"features of {s['clips']} clip(s), {s['frames']} frames ({s['frames_per_cpu_s']:.0f} frames per CPU-second, "
        f"+ {s['fields_setup_cpu_s']:.1f} CPU-s loading the objects' fields) -> datasets/{a.name}/features/"
    )
    return 0


def _add_retarget(sub) -> None:
    p = sub.add_parser(
        "retarget",
        help="mocap -> G1 clips by mink IK (datasets/<NAME>/retargeted/); the ingested human clips go to "
        "datasets/<NAME>/human/",
    )
    _stage_args(p)
    _run_args(p)
    p.add_argument(
        "--height",
        type=float,
        default=None,
        help="subject height override in metres, 0.5-2.5 (a subject outside 1.0-2.3 m needs it)",
    )
    p.add_argument(
        "--fps",
        type=float,
        default=None,
        help="frame rate in Hz of input files that carry none (keypoints CSV without a time column, keypoints .npz "
        "without fps) and the sampling rate of MCAP streams; files with their own rate keep it",
    )
    p.add_argument(
        "--units",
        default=None,
        choices=("auto", "m", "cm", "mm", "inch"),
        help="units of input files that do not say: BVH (default auto: guessed from the subject's height) and "
        "keypoints (default m, or the .npz's own)",
    )
    p.add_argument(
        "--object-mesh",
        default=None,
        help="the object's mesh for OMOMO .pt input (default: <object>.obj beside it, by the file's name)",
    )
    p.add_argument(
        "--augment-scales",
        default=None,
        help="geometry augmentation (retarget.augment): every clip once per object scale of this comma list, e.g. "
        "0.6,0.8,1,1.2,1.4 (1: the clip itself; sx:sy:sz per axis)",
    )
    p.add_argument(
        "--augment-shapes",
        default="box",
        help="with --augment-scales: the shapes, box (the object's own) and/or cylinder (a box as a circular "
        "cylinder), comma list (default box)",
    )
    p.set_defaults(func=_cmd_retarget, writes="name")


def _add_import(sub) -> None:
    p = sub.add_parser(
        "import",
        help="G1 motions retargeted by other tools (BeyondMimic/mjlab .npz, GMR .pkl, HDMI motion folders) -> "
        "datasets/<NAME>/retargeted/, for physicalize and features",
    )
    p.add_argument("--input", default=None, help="a G1 motion file or HDMI motion folder, or a folder of them")
    p.add_argument("--name", default="default", help="dataset name: writes datasets/<NAME>/retargeted/")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output dataset")
    p.add_argument(
        "--object-mesh", default=None, help="mesh of the object the motions carry (default: <object>.obj beside them)"
    )
    p.add_argument("--object-mass", type=float, default=None, help="the object's mass in kg (default 2)")
    add_joint_names(p)
    _run_args(p)
    p.set_defaults(func=_cmd_import, writes="name")


def _add_physicalize(sub) -> None:
    p = sub.add_parser(
        "physicalize", help="retargeted clips -> simulated state-action data (datasets/<NAME>/physicalized/)"
    )
    _stage_args(p)
    _run_args(p)
    p.add_argument(
        "--teacher",
        default="base",
        help="tracking teacher: base (whole-body QP controller) or base+residual:<checkpoint> "
        "(the QP's joint targets plus a learned residual trained by `lessmimic physicalize-residual`)",
    )
    p.add_argument(
        "--profile", default="mjlab", help="actuator profile of the actions: mjlab or lessmimic_demo (default mjlab)"
    )
    p.add_argument(
        "--keep-invalid",
        action="store_true",
        help="also write clips that fail validation (they are always in report.json)",
    )
    p.add_argument(
        "--search-budget",
        type=float,
        default=None,
        help="the budget of the search with the QP in the loop where the teacher's rollout falls, as the simulated "
        "frames of this many children per second of motion (physicalize/search/; 0: no search; default: "
        "SearchConfig.children_per_s, ~12-20 CPU-s per second of motion at most)",
    )
    p.set_defaults(func=_cmd_physicalize, writes="name")


def _add_features(sub) -> None:
    p = sub.add_parser(
        "features", help="physicalized data -> distance-field interaction features (datasets/<NAME>/features/)"
    )
    p.add_argument(
        "--name",
        default="default",
        help="dataset name: reads datasets/<NAME>/physicalized/, writes datasets/<NAME>/features/",
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing output dataset")
    _run_args(p)
    p.add_argument(
        "--links",
        default=None,
        help="comma-separated G1 body names for observation.df (default: pelvis, torso, hips, knees, "
        "ankles, shoulders, elbows, wrists)",
    )
    p.set_defaults(func=_cmd_features, writes="name")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="lessmimic", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = ap.add_subparsers(dest="command", required=True)
    stages = (_add_retarget, _add_import, _add_physicalize, add_residual, _add_features)
    for add in (*stages, add_train, add_corpus, add_tools, add_export_motion):
        add(sub)
    return ap


def _run(args: argparse.Namespace) -> int:
    """The command; one that writes into ``datasets/<NAME>/`` holds its lock, keeps what libraries write inside its
    outputs (:mod:`pipeline.stage.outputs`) and, when it fails (an error, or exit status 1: nothing written), leaves
    the folder as it found it (:class:`pipeline.stage.undo.Undo`)."""
    with writer_lock(getattr(args, args.writes) if getattr(args, "writes", None) else None) as lock:
        if lock is None:
            return args.func(args)
        undo = Undo(lock.parent)
        try:
            with temporary_arrow_cache(), mujoco_log_into(lock.parent / "logs" / "mujoco.log"):
                status = args.func(args)
        except (Exception, SystemExit):
            undo.restore()
            raise
        except BaseException:  # Ctrl-C: what is finished stays for the resume
            undo.drop()
            raise
        if status == 1:
            undo.restore()
        else:
            undo.drop()
        return status


def main(argv: list[str] | None = None) -> int:
    """Run the command; a bad input, a refused lock, an OS error or Ctrl-C is one ``error:`` line on stderr."""
    args = build_parser().parse_args(argv)
    try:
        return _run(args)
    except (InputError, FileExistsError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"error: interrupted (Ctrl-C): {INTERRUPTED}", file=sys.stderr)
        return 130
    except OSError as exc:
        print(f"error: {os_error_line(exc)}", file=sys.stderr)
        return 2


def run() -> None:
    """Console-script entry point."""
    sys.exit(main())


if __name__ == "__main__":
    run()
