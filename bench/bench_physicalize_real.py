"""Physicalize on real human-object mocap: every clip of the given folders (default: ``../shared/mocap``'s
``interact/``, ``omomo/`` and ``intermimic/``), retargeted then physicalized as ``make retarget physicalize``
does, one table row each:

* ``valid``;
* ``rejected: <class>``: the reference asks what the robot cannot do, decided before tracking
  (:mod:`physicalize.feasibility`), with the figure that proves it;
* ``failed: <class>``: tracked and invalid (:func:`physicalize.validate.failure_class`): fell before the
  first contact (approach or locomotion), fell at contact (the first second of it), fell while holding,
  object lost, joint limits, penetration, foot sliding, tracking error, or error (an exception).

Each row also says how the hands hold the object where the human lifts it with both hands (object 3 cm above its
first height, both human wrists touching it): ``opp`` is the mean of ``n_l . n_r`` (the object's outward surface
normals nearest each wrist: -1 opposite sides) for the human's wrists and for the retargeted G1's, ``human/G1``
(``-``: no such frames): a retargeting that turns a squeeze into a one-sided hold starts a grasp physics cannot keep.

Then per object kind and over all: valid / rejected / failed counts, ``valid`` over the clips not rejected
(the issue's bar: >= 0.8), ``rejected`` over all clips (<= 0.25), and the speed of the physicalize pass in
simulated seconds per CPU-second (>= 2; retargeting is timed apart). Clips run in ``--jobs`` worker processes
(one clip per process at a time: timings are per core). ``--json`` keeps every clip's figures.

Run: ``make bench-physicalize-real [FOLDERS="a b"] [JOBS=2]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import torch

torch.set_num_threads(1)

import numpy as np  # noqa: E402

from physicalize.clip import physicalize_clip  # noqa: E402
from pipeline.distance.field import ObjectField  # noqa: E402
from pipeline.geometry import MeshGeometry  # noqa: E402
from pipeline.readers import read_clips  # noqa: E402
from pipeline.robot import HAND_BODIES  # noqa: E402
from pipeline.stage.executor import map_ordered  # noqa: E402
from pipeline.terms.link_motion import link_motion  # noqa: E402
from retarget.clip import retarget_clip  # noqa: E402

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "mocap"
DEFAULT_FOLDERS = [SHARED / "interact", SHARED / "omomo", SHARED / "intermimic"]


def object_kind(path: Path) -> str:
    """``largebox`` from ``sub8_largebox_001.pt`` (the OMOMO naming: subject, object, take)."""
    parts = path.stem.split("_")
    return parts[1] if len(parts) >= 3 else path.stem


def hand_opposition(human, robot) -> tuple[float | None, float | None]:
    """Mean ``n_l . n_r`` of the human's and the G1's wrists where the human lifts the object with both hands."""
    if human.contacts is None or not robot.objects:
        return None, None
    h = human.resampled(robot.fps)
    wrists = [h.skeleton.index(n) for n in ("left_wrist", "right_wrist") if n in h.skeleton.joint_names]
    if len(wrists) < 2:
        return None, None
    o_h, o_r = h.objects[0], robot.objects[0]
    T = min(h.frames, robot.frames)
    frames = np.flatnonzero(h.contacts[:T, wrists].all(axis=1) & (o_r.pose[:T, 2] > o_r.pose[0, 2] + 0.03))
    if not frames.size:
        return None, None
    field = ObjectField.from_geometry(
        o_r.geometry, **({"cache": False} if isinstance(o_r.geometry, MeshGeometry) else {})
    )
    links = link_motion(robot.qpos[frames], np.zeros((len(frames), 35)), HAND_BODIES, robot.source).pos
    out = []
    for pts, poses in ((h.joint_pos[frames][:, wrists], o_h.pose[frames]), (links, o_r.pose[frames])):
        g = np.asarray(field.query_links(pts, poses).grad)
        out.append(float(np.mean(np.einsum("ti,ti->t", g[:, 0], g[:, 1]))))
    return out[0], out[1]


def run_clip(path: Path) -> dict:
    """Retarget and physicalize one clip file; its figures, verdict and timings."""
    row = {"clip": path.name, "folder": path.parent.name, "object": object_kind(path)}
    try:
        human = read_clips(path)[0]
        c0 = time.process_time()
        robot = retarget_clip(human)[0]
        row["retarget_cpu_s"] = time.process_time() - c0
        row["opposition_human"], row["opposition_g1"] = hand_opposition(human, robot)
        c0 = time.process_time()
        _, roll, figures, _ = physicalize_clip(robot)
        row["physicalize_cpu_s"] = time.process_time() - c0
        row["seconds"] = robot.frames / robot.fps
    except Exception as exc:  # noqa: BLE001 - a clip that raises is a row of the table, not the end of the bench
        figures = {"valid": False, "reason": f"error: {type(exc).__name__}: {exc}", "failure": "error"}
    row.update(figures)
    row["verdict"] = (
        "valid"
        if figures["valid"]
        else f"rejected: {figures['rejected']}"
        if figures.get("rejected")
        else f"failed: {figures.get('failure', 'unclassified')}"
    )
    return row


def clip_files(folders: list[Path]) -> list[Path]:
    files = []
    for folder in folders:
        if folder.is_dir():
            files += sorted(p for p in folder.iterdir() if p.suffix in (".pt", ".bvh", ".npz", ".c3d", ".mcap"))
        else:
            print(f"(skipped {folder}: not present)", file=sys.stderr)
    return files


def summary(rows: list[dict]) -> list[str]:
    lines = []
    groups = {"all": rows, **{k: [r for r in rows if r["object"] == k] for k in sorted({r["object"] for r in rows})}}
    for name, group in groups.items():
        n = len(group)
        valid = sum(r["valid"] for r in group)
        rejected = sum(r["verdict"].startswith("rejected") for r in group)
        kept = n - rejected
        sim = sum(r.get("seconds", 0.0) for r in group)
        cpu = sum(r.get("physicalize_cpu_s", 0.0) for r in group)
        lines.append(
            f"{name:12s} clips {n:3d}  valid {valid:3d}  rejected {rejected:3d}  failed {kept - valid:3d}  "
            f"valid/not-rejected {valid / max(kept, 1):.2f}  rejected/all {rejected / max(n, 1):.2f}  "
            f"physicalize {sim / max(cpu, 1e-9):.2f}x real time per core"
        )
    causes = Counter(r["verdict"] for r in rows if not r["valid"])
    lines.append("outcomes: " + ", ".join(f"{k} {v}" for k, v in causes.most_common()))
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folders", nargs="*", type=Path, default=DEFAULT_FOLDERS)
    ap.add_argument("-j", "--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--json", type=Path, default=None, help="also write every clip's figures here")
    args = ap.parse_args()
    files = clip_files(args.folders)
    t0 = time.perf_counter()
    rows = map_ordered(run_clip, files, jobs=args.jobs, desc="real clips")
    print(f"{'clip':28s}{'object':12s}{'s':>6s}{'rt/core':>9s}{'opp':>12s}  verdict: reason")
    for r in rows:
        rt = r.get("seconds", 0.0) / max(r.get("physicalize_cpu_s", 1e9), 1e-9)
        reason = r["reason"].removeprefix(f"{r['verdict']}: ")
        opp = "/".join("-" if v is None else f"{v:.2f}" for v in (r.get("opposition_human"), r.get("opposition_g1")))
        head = f"{r['clip']:28s}{r['object']:12s}{r.get('seconds', 0):6.1f}{rt:9.2f}{opp:>12s}"
        print(f"{head}  {r['verdict']}: {reason[:100]}")
    for line in summary(rows):
        print(line)
    print(f"({len(rows)} clips in {time.perf_counter() - t0:.0f} s wall on {args.jobs} worker processes)")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float))


if __name__ == "__main__":
    main()
