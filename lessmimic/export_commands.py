"""``lessmimic export-motion``: a G1 motion dataset in the files other trainers read (:mod:`motion_export`), kept
apart from the per-stage commands of :mod:`lessmimic.cli`."""

from __future__ import annotations

import argparse

from motion_export import FORMAT_NAMES, HDMI_OBJECT_NAMES, MOTION_STAGES


def _cmd_export_motion(a: argparse.Namespace) -> int:
    from motion_export.stage import export_motion

    s = export_motion(
        a.name,
        a.format,
        a.out,
        stage=a.stage,
        episode=a.episode,
        include_invalid=a.all,
        overwrite=a.overwrite,
        hdmi_object=a.hdmi_object,
    )
    print(
        f"exported {len(s.episodes)} episode(s) of datasets/{a.name}/{a.stage}/ as {s.fmt} -> {s.out}/: "
        f"{s.frames} frames ({s.seconds:.1f} s of motion), {len(s.files)} files, {s.bytes / 1e6:.2f} MB "
        f"in {s.write_s:.2f} s"
    )
    return 0


def add_export_motion(sub) -> None:
    p = sub.add_parser(
        "export-motion",
        help="a physicalized (or retargeted) dataset's G1 motions as mjlab .npz, BeyondMimic .npz (Isaac Lab order), "
        "HDMI folders, GMR .pkl or Unitree .csv, each with a JSON sidecar (datasets/<NAME>/export/<FORMAT>/)",
    )
    p.add_argument("--name", default="default", help="dataset name: reads datasets/<NAME>/<STAGE>/ (default: default)")
    p.add_argument("--format", required=True, help=f"one of {', '.join(FORMAT_NAMES)}")
    p.add_argument(
        "--stage", default=MOTION_STAGES[0], help=f"the dataset exported: {' or '.join(MOTION_STAGES)} (default "
        f"{MOTION_STAGES[0]})",
    )  # fmt: skip
    p.add_argument("--episode", type=int, default=None, help="export this episode index only (default: every one)")
    p.add_argument("--all", action="store_true", help="also the episodes that failed validation (default: valid only)")
    p.add_argument(
        "--out", default=None, help="output folder (default datasets/<NAME>/export/<FORMAT>/; <FORMAT>-retargeted/)"
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p.add_argument(
        "--hdmi-object",
        default=None,
        choices=HDMI_OBJECT_NAMES,
        help="hdmi: name the (first) object as HDMI's asset, which HDMI finds its object body by (its task's "
        "object_asset_name; default: the dataset's object name)",
    )
    p.set_defaults(func=_cmd_export_motion)
