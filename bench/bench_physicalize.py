"""Physicalize validity and speed per clip, side by side for the three references the base teacher
can track: ``raw`` (the retargeted motion), ``planned`` (its posture with the ZMP preview-planned
CoM) and ``feasible`` (the whole body re-solved by IK onto the plan: the stage's default), then
``feasible/g0``: the feasible reference with the base teacher's first QP gain set only (the other rows try
the sets of :data:`physicalize.wbc_config.TEACHER_GAINS` in order and keep the first valid rollout; ``gains`` is the
set kept, ``tries`` how many ran), and ``feasible+res``: the feasible reference with the base teacher plus a
learned residual trained on that clip at SMOKE scale (``--residual-iterations`` x 16 envs of PPO on one core, default
50; 0
skips it; training time not in ``rt``).

Run: ``make bench-physicalize``. Clips: the four embedded default clips and, when ``../shared/mocap``
is present, the OMOMO box clip, the InterMimic table clip and the PyMO walk. Each clip is first
retargeted (not timed), then physicalized by :func:`physicalize.clip.physicalize_clip` (timed:
scene build, reference, plan and closed-loop tracking on one core). ``rt`` is simulated seconds
per wall second, ``rt/core`` per CPU second (robust to a shared, loaded machine: everything runs on one
thread); the issue's bar is >= 5 per core. ``ref tau``: the largest static torque the tracked reference asks of an
upper-body motor, as a fraction of its limit (:mod:`physicalize.static_torque`); ``grip out``: the share of held frames
whose planned hand forces leave the hands' friction cones (:func:`physicalize.grasp.press_force`). First, a robustness
table:
per default task, the valid count over ``--seeds`` synthetic seeds (each moves the objects a few cm). Then the
teacher's gait envelope: 10-step G1 walks (:func:`physicalize.synthetic_gait.walk_with_turn`, straight and turning 90
degrees) over step length x (swing, double support) timing, each cell ``ok`` (walked to the end, root within 0.25 m
of the reference), ``ok gK`` (walked with gain set K) or the fraction of the walk simulated before it failed.
Then an object mass sweep: each clip with objects, its objects' mass set to each of :data:`MASSES_KG` (a held or
pushed object's mass changes the loads but not the reference), each cell ``ok`` or the first failure: how far a clip
sits from the validity bars.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import torch

torch.set_num_threads(1)

import numpy as np  # noqa: E402

from ingest.default_input import default_clips  # noqa: E402
from physicalize.clip import physicalize_clip  # noqa: E402
from physicalize.problem import REFERENCES  # noqa: E402
from physicalize.residual import train_residual  # noqa: E402
from physicalize.rollout import initial_state, simulate  # noqa: E402
from physicalize.synthetic_gait import gait_reference, walk_with_turn  # noqa: E402
from physicalize.wbc import WholeBodyController  # noqa: E402
from physicalize.wbc_config import TEACHER_GAINS  # noqa: E402
from pipeline.readers import read_clips  # noqa: E402
from pipeline.scene import build_scene  # noqa: E402
from retarget.clip import retarget_clip  # noqa: E402

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "mocap"
GAIT_STEPS_M = (0.1, 0.2, 0.3, 0.4, 0.5)  # centre-line advance per step (each foot moves twice that)
GAIT_TIMINGS_S = ((0.35, 0.10), (0.40, 0.10), (0.45, 0.12), (0.50, 0.15), (0.60, 0.20))  # (swing, double support)
GAIT_TURNS_RAD = (0.0, np.pi / 2)
MASSES_KG = (
    0.5,
    1.0,
    1.5,
    2.5,
    3.0,
)  # object masses of the sweep (the scene's default is 2 kg where the input gives none)
REAL = ["omomo/sub3_largebox_003.pt", "intermimic/sub2_largetable_000.pt", "bvh/pymo_walk_120hz.bvh"]
COLUMNS = [
    ("valid", "valid"),
    ("fell", "fell"),
    ("frames_simulated", "sim/ref"),
    ("mpjpe_m", "mpjpe"),
    ("root_pos_err_max_m", "root max"),
    ("foot_slide_frac_1cm_per_frame", "slide"),
    ("penetration_max_m", "pen max"),
    ("torque_saturation_frac", "sat"),
    ("object_pos_err_m", "obj err"),
    ("reference_static_torque_ratio_max", "ref tau"),
    ("reference_grasp_outside_friction_frac", "grip out"),
    ("teacher_gains", "gains"),
    ("teacher_attempts", "tries"),
    ("realtime_factor", "rt"),
    ("realtime_factor_per_core", "rt/core"),
]


def _clips():
    for c in default_clips():
        yield f"synthetic:{c.task}", c
    for rel in REAL:
        path = SHARED / rel
        if path.is_file():
            yield path.name, read_clips(path)[0]
        else:
            print(f"(skipped {rel}: ../shared/mocap not present)", file=sys.stderr)


def _cell(key, f) -> str:
    v = f.get(key, float("nan"))
    if key == "frames_simulated":
        return f"{v}/{f['frames']}" if "frames" in f else "rejected"
    if key in ("teacher_gains", "teacher_attempts"):
        return str(v)
    if isinstance(v, bool):
        return "yes" if v else "no"
    return f"{v:.3f}"


def _seed_table(n: int) -> None:
    """Per default task, on how many of the synthetic seeds ``0..n-1`` (each moves the objects a few cm) the
    clip is valid with the feasible reference and the base teacher, and the reasons of the others."""
    counts: dict[str, list] = {}
    for seed in range(n):
        for c in default_clips(seed=seed):
            _, _, f, _ = physicalize_clip(retarget_clip(c)[0])
            counts.setdefault(c.task, []).append((seed, f))
    print(f"robustness over synthetic seeds 0-{n - 1} (feasible reference, base teacher):")
    for task, runs in counts.items():
        bad = [f"seed {s}: {f['reason'][:50]}" for s, f in runs if not f["valid"]]
        print(
            f"  {task:9s} valid {sum(f['valid'] for _, f in runs)}/{len(runs)}"
            + (f"  ({'; '.join(bad[:3])}{' ...' if len(bad) > 3 else ''})" if bad else ""),
            flush=True,
        )


def _gait_cell(scene, step_m: float, swing_s: float, double_s: float, turn_rad: float) -> str:
    """``ok`` (the first gain set walked it), ``ok gK`` (gain set K did), or the fraction of the walk the first set
    simulated before it fell or its root strayed 0.25 m."""
    qpos, _ = walk_with_turn(scene, steps=10, step_m=step_m, turn_rad=turn_rad, swing_s=swing_s, double_s=double_s)
    ref = gait_reference(scene, qpos)
    first = None
    for k, gains in enumerate(TEACHER_GAINS):
        roll = simulate(
            scene, ref, WholeBodyController(scene.model, scene.profile, gains), *initial_state(scene, ref, {})
        )
        root_err = np.linalg.norm(roll.qpos[:, :2] - ref.qpos[: roll.frames, :2], axis=1)
        if roll.fell_at is None and root_err.max() <= 0.25:
            return "ok" if k == 0 else f"ok g{k}"
        if first is None:
            first = (int(np.argmax(root_err > 0.25)) if (root_err > 0.25).any() else roll.frames) / len(ref.qpos)
    return f"{first:.2f}"


def _gait_table() -> None:
    """The base teacher's gait envelope (see the module docstring): rows (swing, double support) [s], columns
    the step length [m] and the mean speed it gives."""
    scene = build_scene()
    cells = []
    for turn in GAIT_TURNS_RAD:
        print(
            f"gait envelope, 10 steps turning {np.degrees(turn):.0f} deg (ok, ok gK: walked by gain set K, else the "
            "fraction the first set walked):"
        )
        print(f"  {'swing/ds [s]':14s}" + "".join(f"{f'{s:.1f} m':>18s}" for s in GAIT_STEPS_M))
        for swing, ds in GAIT_TIMINGS_S:
            row = [_gait_cell(scene, s, swing, ds, turn) for s in GAIT_STEPS_M]
            cells += row
            print(
                f"  {f'{swing:.2f}/{ds:.2f}':14s}"
                + "".join(f"{f'{c} ({s / (swing + ds):.2f} m/s)':>18s}" for c, s in zip(row, GAIT_STEPS_M)),
                flush=True,
            )
    print(
        f"gait envelope: {cells.count('ok')}/{len(cells)} walks with the first gain set, "
        f"{sum(c.startswith('ok') for c in cells)}/{len(cells)} with any"
    )


def _mass_table(robots: list) -> None:
    """Per retargeted clip with objects (``robots``: (name, RobotClip)), validity with its objects' mass set to each
    of :data:`MASSES_KG` (feasible reference, base teacher with its gain sets)."""
    print("object mass sweep (feasible reference, base teacher; ok, else the first failure):")
    print(f"  {'clip':24s}" + "".join(f"{f'{kg:g} kg':>26s}" for kg in MASSES_KG))
    for name, robot in robots:
        if not robot.objects:
            continue
        cells = []
        for kg in MASSES_KG:
            f = physicalize_clip(replace(robot, objects=tuple(replace(o, mass=kg) for o in robot.objects)))[2]
            cells.append("ok" if f["valid"] else f["reason"].split(";")[0][:24])
        print(
            f"  {name:24s}" + "".join(f"{c:>26s}" for c in cells) + f"  valid {cells.count('ok')}/{len(cells)}",
            flush=True,
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--residual-iterations",
        type=int,
        default=50,
        help="PPO iterations (x 16 envs) of the smoke residual per clip; 0: skip",
    )
    ap.add_argument(
        "--seeds",
        type=int,
        default=10,
        help="synthetic seeds 0..N-1 of the robustness table (feasible reference, base teacher); 0: skip",
    )
    ap.add_argument("--no-gait", action="store_true", help="skip the gait envelope table")
    ap.add_argument("--no-mass", action="store_true", help="skip the object mass sweep")
    args = ap.parse_args()
    if args.seeds:
        _seed_table(args.seeds)
    if not args.no_gait:
        _gait_table()
    robots = [(name, retarget_clip(human)[0]) for name, human in _clips()]
    if not args.no_mass:
        _mass_table(robots)
    print(f"{'clip':24s}{'reference':14s}" + "".join(f"{h:>10s}" for _, h in COLUMNS) + "  reason")
    kinds = [*REFERENCES, "feasible/g0", *(["feasible+res"] if args.residual_iterations else [])]
    valid = {k: [] for k in kinds}
    seconds = {k: [0.0, 0.0] for k in kinds}  # simulated, CPU
    with tempfile.TemporaryDirectory() as tmp:
        for name, robot in robots:
            for kind in kinds:
                if kind == "feasible+res":
                    ckpt = train_residual(robot, args.residual_iterations, 16, 0, Path(tmp) / "residual.pt")
                    _, roll, f, _ = physicalize_clip(robot, teacher=f"base+residual:{ckpt}")
                else:
                    _, roll, f, _ = physicalize_clip(
                        robot, reference=kind.split("/")[0], gains=TEACHER_GAINS[:1] if kind.endswith("/g0") else None
                    )
                valid[kind].append(f["valid"])
                sim = 0.0 if roll is None else roll.frames / robot.fps  # a rejected clip is not simulated
                cpu = sim / f["realtime_factor_per_core"] if roll is not None else 0.0
                seconds[kind] = [seconds[kind][0] + sim, seconds[kind][1] + cpu]
                print(
                    f"{name:24s}{kind:14s}"
                    + "".join(f"{_cell(k, f):>10s}" for k, _ in COLUMNS)
                    + f"  {f['reason'][:60]}",
                    flush=True,
                )
    for kind, v in valid.items():
        sim, cpu = seconds[kind]
        print(
            f"valid fraction ({kind}): {sum(v)}/{len(v)} = {sum(v) / max(len(v), 1):.2f}; the whole pass "
            f"{sim / max(cpu, 1e-9):.2f}x real time per core"
        )


if __name__ == "__main__":
    main()
