"""Physicalize on real human-object mocap: every clip of the given folders (default: ``../shared/mocap``'s
``interact/``, ``omomo/`` and ``intermimic/``), retargeted then physicalized as ``make retarget physicalize``
does, one table row each, with the take's kind (:func:`pipeline.take.take_kind`, from the object's own
reference track: ``slide``, ``lift``, ``overhead`` or ``small move``, with the object's rise and travel [m]) and
its verdict:

* ``valid``;
* ``rejected: <class>``: the reference asks what the robot cannot do, decided before tracking
  (:mod:`physicalize.feasibility`), with the figure that proves it (printed whole);
* ``failed: <class>``: tracked and invalid (:func:`physicalize.validate.failure_class`): fell before the
  first contact (approach or locomotion), fell at contact (the first second of it), fell while holding,
  object lost, joint limits, penetration, foot sliding, tracking error, or error (an exception).

Each row also says how the hands hold the object where the human holds it with both hands, lifted or not (each
hand labelled in contact or within 2 cm of the object: :func:`pipeline.take.held_frames`): ``opp`` is the
mean of ``n_l . n_r`` (the object's outward surface normals nearest each wrist: -1 opposite sides) for the human's
wrists and for the retargeted G1's, ``human/G1`` (``-``: no such frames): a retargeting that turns a squeeze into
a one-sided hold starts a grasp physics cannot keep.

Then over all, per take kind and per object: valid / rejected / failed counts, ``valid`` over the clips not
rejected (the bars: >= 0.4 after the world's physics and clean starts, >= 0.8 with the object in the teacher's
loop), ``rejected`` over all clips (<= 0.35), the speed of the physicalize pass in simulated seconds per CPU-second
over the clips it tracked to the end (>= 2; retargeting is timed apart), and the yield:
valid frames (50 Hz, the robot clip's) per core-hour, ``3600 * sum(frames of the valid clips) /
sum(retarget + physicalize CPU-seconds of every clip)``, rejected and failed ones included (their CPU is spent
too). Clips run in ``--jobs`` worker processes (one clip per process at a time: timings are per core); with fewer
clips than jobs, each clip's search spreads its children over the idle ones (:mod:`physicalize.search.children`; the
same verdicts, and their CPU-seconds count).
``--json`` keeps every clip's figures. ``--sensitivity`` adds a row per end of the physics ranges: every take
again with its objects' mass, hand and floor friction at the low, then at the high end of its kind's ranges
(:mod:`pipeline.materials`): how much of the result rests on the table's nominal values. ``--guide S`` holds every
object on its track by a virtual wrench at scale ``S`` in every rollout, the search's included
(:mod:`physicalize.guidance`): what the robot does when the object goes where the reference says (never valid).

Run: ``make bench-physicalize-real [FOLDERS="a b"] [JOBS=2] [BENCH_ARGS=--sensitivity]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from dataclasses import replace
from functools import partial
from pathlib import Path

import torch

torch.set_num_threads(1)

import numpy as np  # noqa: E402

from physicalize.clip import physicalize_clip, robot_alone  # noqa: E402
from physicalize.search.beam import SearchConfig  # noqa: E402
from physicalize.stage import search_workers  # noqa: E402
from pipeline.materials import object_physics_for  # noqa: E402
from pipeline.readers import read_clips  # noqa: E402
from pipeline.stage.executor import map_ordered  # noqa: E402
from pipeline.take import KINDS, held_frames, object_field, take_kind  # noqa: E402
from retarget.clip import retarget_clip  # noqa: E402
from retarget.grip import g1_opposition  # noqa: E402

SEARCH = SearchConfig()
SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "mocap"
DEFAULT_FOLDERS = [SHARED / "interact", SHARED / "omomo", SHARED / "intermimic"]


def object_kind(path: Path) -> str:
    """``largebox`` from ``sub8_largebox_001.pt`` (the OMOMO naming: subject, object, take)."""
    parts = path.stem.split("_")
    return parts[1] if len(parts) >= 3 else path.stem


def g1_hand_opposition(human, robot) -> float | None:
    """Mean ``n_l . n_r`` of the G1's hands over the frames the human holds the object with both hands
    (:func:`pipeline.take.held_frames`, on the human resampled to the robot's rate;
    :func:`retarget.grip.g1_opposition`); the human's own is the retargeted clip's
    ``provenance["human_hand_opposition"]`` (:func:`pipeline.take.human_hold`)."""
    if not human.objects or not robot.objects:
        return None
    h = human.resampled(robot.fps)
    field = object_field(h)  # the robot's object is the human's, placed anew: same geometry
    frames = np.flatnonzero(held_frames(h, field)[: robot.frames])
    if not frames.size:
        return None
    return g1_opposition(field, robot.qpos, robot.objects, frames, robot.source)


def with_physics(human, end: str):
    """The take with its objects' mass and frictions at ``end`` of their kind's ranges (:mod:`pipeline.materials`)."""
    if end == "nominal":
        return human
    objects = []
    for o in human.objects:
        p, _ = object_physics_for(o.name, end)
        objects.append(replace(o, mass=p.mass, friction=p.friction, floor_friction=p.floor_friction))
    return replace(human, objects=tuple(objects))


def run_clip(
    path: Path,
    end: str = "nominal",
    robot_only: bool = False,
    search: SearchConfig | None = SEARCH,
    workers: int = 1,
    guide: float = 0.0,
) -> dict:
    """Retarget and physicalize one clip file, its objects' physics at ``end`` of their ranges (``robot_only``: its
    body motion alone, :func:`physicalize.clip.robot_alone`), with the ``search`` where the teacher falls (None: no
    search; its children in ``workers`` processes, whose CPU-seconds count), ``guide``: the objects held on their
    tracks at that scale (:mod:`physicalize.guidance`; 0: not); its figures, verdict (and the verdict
    before the search, ``verdict_before``) and timings."""
    row = {"clip": path.name, "folder": path.parent.name, "object": object_kind(path), "kind": "unread"}
    stage, c0 = "retarget_cpu_s", time.process_time()
    try:
        human = with_physics(read_clips(path)[0], end)
        if human.objects:
            kind = take_kind(human.objects[0].pose)
            row.update(kind=kind.kind, rise_m=kind.rise_m, travel_m=kind.travel_m)
        else:
            row["kind"] = "no object"
        c0 = time.process_time()
        robot = retarget_clip(human)[0]
        row["retarget_cpu_s"] = time.process_time() - c0
        row["frames"] = robot.frames
        row["opposition_human"] = robot.provenance.get("human_hand_opposition")
        row["opposition_g1"] = g1_hand_opposition(human, robot)
        stage, c0 = "physicalize_cpu_s", time.process_time()
        body = robot_alone(robot) if robot_only else robot
        _, roll, figures, _ = physicalize_clip(body, search=search, search_workers=workers, guide=guide)
        row["physicalize_cpu_s"] = time.process_time() - c0 + figures.get("search", {}).get("worker_cpu_s", 0.0)
        row["seconds"] = robot.frames / robot.fps
    except Exception as exc:  # noqa: BLE001 - a clip that raises is a row of the table, not the end of the bench
        row.setdefault(stage, time.process_time() - c0)  # the CPU it spent counts against the yield
        figures = {"valid": False, "reason": f"error: {type(exc).__name__}: {exc}", "failure": "error"}
    row.update(figures)
    searched = figures.get("search")
    row["searched"] = searched is not None
    row["search_cpu_s"] = searched["cpu_s"] if searched else 0.0
    row["verdict_before"] = f"failed: {searched['failure_before']}" if searched else None
    row["verdict"] = (
        "valid"
        if figures["valid"]
        else f"rejected: {figures['rejected']}"
        if figures.get("rejected")
        else f"failed: {figures.get('failure', 'unclassified')}"
    )
    return row


def verdict_line(row: dict) -> str:
    """``verdict: reason``; a rejection's reason whole (its class and the figure that proves it), others cut to
    100 characters."""
    reason = row["reason"].removeprefix(f"{row['verdict']}: ")
    return f"{row['verdict']}: {reason if row.get('rejected') else reason[:100]}"


TRACE = (
    ("fell_at_s", "fell", "{:5.2f}"),
    ("drift_onset_s", "drift@", "{:5.2f}"),
    ("drift_onset_support", "on", "{:>6s}"),
    ("pelvis_drift_pre_fall_m", "pel", "{:5.2f}"),
    ("com_drift_pre_fall_m", "com", "{:5.2f}"),
    ("step_adjustments", "steps", "{:3d}"),
    ("step_adjust_max_m", "max", "{:4.2f}"),
    ("support_mismatch_frac", "mism", "{:4.2f}"),
    ("reference_single_support_max_s", "ss", "{:4.1f}"),
    ("plan_zmp_outside_max_m", "zmp", "{:4.2f}"),
)


OBJECT_TRACE = (
    ("object_drift_s", "object strayed@", "{:5.2f}"),
    ("object_drift_cause", "", "{}"),
    ("object_drift_along_m", "along", "{:+5.2f}"),
    ("object_drift_lateral_m", "across", "{:+5.2f}"),
    ("object_drift_yaw_deg", "yaw", "{:+4.0f}"),
    ("object_drift_hands_planned", "hands planned", "{:d}"),
    ("object_drift_hands_touching", "touching", "{:d}"),
)


def trace_line(row: dict, fields: tuple = TRACE) -> str:
    """The balance trace of a row (:mod:`physicalize.balance`): when it fell, when and on which support the pelvis
    drifted, the drift 0.2 s before the fall, the capture-point steps, planned vs measured foot contacts, the longest
    single support and the planned ZMP's excursion from the support; or, with ``fields`` :data:`OBJECT_TRACE`, where
    its object strayed (:mod:`physicalize.object_trace`)."""
    out = []
    for key, name, fmt in fields:
        v = row.get(key)
        out.append(f"{name} {'-' if v is None else fmt.format(v).strip()}")
    return "  ".join(out)


def clip_files(folders: list[Path]) -> list[Path]:
    files = []
    for folder in folders:
        if folder.is_dir():
            files += sorted(p for p in folder.iterdir() if p.suffix in (".pt", ".bvh", ".npz", ".c3d", ".mcap"))
        else:
            print(f"(skipped {folder}: not present)", file=sys.stderr)
    return files


def valid_frames_per_core_hour(group: list[dict]) -> float:
    """The yield: ``3600 * sum(frames of the valid clips) / sum(retarget + physicalize CPU-s of every clip)``."""
    frames = sum(r.get("frames", 0) for r in group if r["valid"])
    cpu = sum(r.get("retarget_cpu_s", 0.0) + r.get("physicalize_cpu_s", 0.0) for r in group)
    return 3600.0 * frames / max(cpu, 1e-9)


def groups(rows: list[dict]) -> dict[str, list[dict]]:
    """The rows over all, per take kind (:data:`pipeline.take.KINDS` order, then any other) and per object."""
    kinds = [k for k in KINDS if any(r["kind"] == k for r in rows)]
    kinds += sorted({r["kind"] for r in rows} - set(kinds))
    objects = sorted({r["object"] for r in rows})
    return {
        "all": rows,
        **{f"kind {k}": [r for r in rows if r["kind"] == k] for k in kinds},
        **{f"object {k}": [r for r in rows if r["object"] == k] for k in objects},
    }


def summary(rows: list[dict]) -> list[str]:
    lines = []
    for name, group in groups(rows).items():
        n = len(group)
        valid = sum(r["valid"] for r in group)
        rejected = sum(r["verdict"].startswith("rejected") for r in group)
        kept = n - rejected
        ran = [r for r in group if "seconds" in r and not r.get("rejected")]  # tracked to the end (rejected: never)
        sim = sum(r["seconds"] for r in ran)
        cpu = sum(r.get("physicalize_cpu_s", 0.0) for r in ran)
        lines.append(
            f"{name:20s} clips {n:3d}  valid {valid:3d}  rejected {rejected:3d}  failed {kept - valid:3d}  "
            f"valid/not-rejected {valid / max(kept, 1):.2f}  rejected/all {rejected / max(n, 1):.2f}  "
            f"physicalize {sim / max(cpu, 1e-9):.2f}x real time per core  "
            f"yield {valid_frames_per_core_hour(group):.0f} valid frames/core-h"
        )
    causes = Counter(r["verdict"] for r in rows if not r["valid"])
    lines.append("outcomes: " + ", ".join(f"{k} {v}" for k, v in causes.most_common()))
    strayed = Counter(r["object_drift_cause"] for r in rows if not r["valid"] and r.get("object_drift_s") is not None)
    if strayed:
        lines.append("objects strayed (failed takes): " + ", ".join(f"{k} {v}" for k, v in strayed.most_common()))
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folders", nargs="*", type=Path, default=DEFAULT_FOLDERS)
    ap.add_argument("-j", "--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--json", type=Path, default=None, help="also write every clip's figures here")
    ap.add_argument(
        "--robot-only",
        action="store_true",
        help="physicalize every take's body motion without its object (hands free) and print each take's balance trace",
    )
    ap.add_argument(
        "--sensitivity",
        action="store_true",
        help="also run every take with its objects' mass and frictions at the low and at the high end of their ranges",
    )
    ap.add_argument(
        "--search-budget",
        type=float,
        default=SEARCH.children_per_s,
        help=f"search children per second of motion where the teacher falls (0: none; {SEARCH.children_per_s:g})",
    )
    ap.add_argument(
        "--search-seed",
        type=int,
        default=SEARCH.seed,
        help=f"the search's first seed (its attempts take the next ones; {SEARCH.seed}): judge a change over several",
    )
    ap.add_argument(
        "--guide",
        type=float,
        default=0.0,
        help="hold every object on its track by a virtual wrench at this scale (physicalize/guidance.py; 0: none): "
        "what the rollout does with the object where the reference says; a guided take is never valid",
    )
    args = ap.parse_args()
    files = clip_files(args.folders)
    t0 = time.perf_counter()
    if args.robot_only and args.sensitivity:
        ap.error("--robot-only and --sensitivity: the physics ranges are the objects'; choose one")
    if not args.search_budget >= 0:
        ap.error(f"--search-budget: must be >= 0 (0: no search), got {args.search_budget:g}")
    if not args.guide >= 0:
        ap.error(f"--guide: must be >= 0 (0: no guidance), got {args.guide:g}")
    search = (
        replace(SEARCH, children_per_s=args.search_budget, seed=args.search_seed) if args.search_budget > 0 else None
    )
    workers = search_workers(args.jobs, len(files))
    run = partial(run_clip, robot_only=args.robot_only, search=search, workers=workers, guide=args.guide)
    rows = map_ordered(run, files, jobs=args.jobs, desc="real clips")
    print(
        f"{'clip':28s}{'object':12s}{'kind':11s}{'rise':>6s}{'trav':>6s}{'s':>6s}{'rt/core':>9s}{'opp':>12s}"
        "  verdict: reason"
    )
    for r in rows:
        rt = r.get("seconds", 0.0) / max(r.get("physicalize_cpu_s", 1e9), 1e-9)
        opp = "/".join("-" if v is None else f"{v:.2f}" for v in (r.get("opposition_human"), r.get("opposition_g1")))
        shape = "".join(f"{r[k]:6.2f}" if k in r else f"{'-':>6s}" for k in ("rise_m", "travel_m"))
        head = f"{r['clip']:28s}{r['object']:12s}{r['kind']:11s}{shape}{r.get('seconds', 0):6.1f}{rt:9.2f}{opp:>12s}"
        print(f"{head}  {verdict_line(r)}")
        if r["searched"]:
            s = r["search"]
            print(
                f"{'':28s}searched: {s['children']} children in {s['attempts']} attempt(s), {s['cpu_s']:.1f} CPU-s "
                f"({s['cpu_s'] / max(r['seconds'], 1e-9):.1f} per second of motion); before: {r['verdict_before']}"
            )
        if args.robot_only:
            print(f"{'':28s}{trace_line(r)}")
        elif r.get("object_drift_s") is not None and not r["valid"]:
            print(f"{'':28s}{trace_line(r, OBJECT_TRACE)}")
    before = [{**r, "valid": False, "verdict": r["verdict_before"]} if r["searched"] else r for r in rows]
    print("before the search: " + summary(before)[0].removeprefix("all").strip())
    for line in summary(rows):
        print(line)
    searched = [r for r in rows if r["searched"]]
    if searched:
        per_s = [r["search_cpu_s"] / max(r["seconds"], 1e-9) for r in searched]
        print(
            f"search: {len(searched)} takes searched, {sum(r['valid'] for r in searched)} made valid; "
            f"{np.mean(per_s):.1f} CPU-s per second of motion (max {max(per_s):.1f}), the take's whole physicalize "
            f"pass {np.mean([r['physicalize_cpu_s'] / r['seconds'] for r in searched]):.1f} (max "
            f"{max(r['physicalize_cpu_s'] / r['seconds'] for r in searched):.1f})"
        )
    if args.sensitivity:
        print("sensitivity (pipeline.materials: every take's mass, hand and floor friction at one end of its ranges):")
        print(f"  {'nominal':8s}" + summary(rows)[0].removeprefix("all").strip())
        for end in ("low", "high"):
            at_end = map_ordered(partial(run, end=end), files, jobs=args.jobs, desc=f"real clips, {end}")
            print(f"  {end:8s}" + summary(at_end)[0].removeprefix("all").strip())
            rows += [{**r, "physics_end": end} for r in at_end]
    print(f"({len(rows)} clips in {time.perf_counter() - t0:.0f} s wall on {args.jobs} worker processes)")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float))


if __name__ == "__main__":
    main()
