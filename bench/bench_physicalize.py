"""Physicalize validity and speed per clip, side by side for the three references the base teacher
can track: ``raw`` (the retargeted motion), ``planned`` (its posture with the ZMP preview-planned
CoM) and ``feasible`` (the whole body re-solved by IK onto the plan: the stage's default), then
``feasible+res``: the feasible reference with the base teacher plus a learned residual trained on
that clip at SMOKE scale (``--residual-iterations`` x 16 envs of PPO on one core, default 50; 0
skips it; training time not in ``rt``).

Run: ``make bench-physicalize``. Clips: the four embedded default clips and, when ``../shared/mocap``
is present, the OMOMO box clip, the InterMimic table clip and the PyMO walk. Each clip is first
retargeted (not timed), then physicalized by :func:`physicalize.stage.physicalize_clip` (timed:
scene build, reference, plan and closed-loop tracking on one core). ``rt`` is simulated seconds
per wall second, ``rt/core`` per CPU second (robust to a shared, loaded machine: everything runs on one
thread); the issue's bar is >= 5 per core. ``ref tau``: the largest static torque the tracked reference asks of an
upper-body motor, as a fraction of its limit (:mod:`physicalize.static_torque`); ``grip out``: the share of held frames
whose planned hand forces leave the hands' friction cones (:func:`physicalize.grasp.press_force`). First, a robustness table:
per default task, the valid count over ``--seeds`` synthetic seeds (each moves the objects a few cm).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import torch

torch.set_num_threads(1)

from physicalize.residual import train_residual  # noqa: E402
from physicalize.stage import REFERENCES, physicalize_clip  # noqa: E402
from pipeline.default_input import default_clips  # noqa: E402
from pipeline.readers import read_clips  # noqa: E402
from retarget.stage import retarget_clip  # noqa: E402

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "mocap"
REAL = ["omomo/sub3_largebox_003.pt", "intermimic/sub2_largetable_000.pt", "bvh/pymo_walk_120hz.bvh"]
COLUMNS = [("valid", "valid"), ("fell", "fell"), ("frames_simulated", "sim/ref"), ("mpjpe_m", "mpjpe"), ("root_pos_err_max_m", "root max"),
           ("foot_slide_frac_1cm_per_frame", "slide"), ("penetration_max_m", "pen max"), ("torque_saturation_frac", "sat"),
           ("object_pos_err_m", "obj err"), ("reference_static_torque_ratio_max", "ref tau"),
           ("reference_grasp_outside_friction_frac", "grip out"), ("realtime_factor", "rt"),
           ("realtime_factor_per_core", "rt/core")]  # fmt: skip


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
        return f"{v}/{f['frames']}"
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
        print(f"  {task:9s} valid {sum(f['valid'] for _, f in runs)}/{len(runs)}" + (f"  ({'; '.join(bad[:3])}{' ...' if len(bad) > 3 else ''})" if bad else ""), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--residual-iterations", type=int, default=50, help="PPO iterations (x 16 envs) of the smoke residual per clip; 0: skip")
    ap.add_argument("--seeds", type=int, default=10, help="synthetic seeds 0..N-1 of the robustness table (feasible reference, base teacher); 0: skip")
    args = ap.parse_args()
    if args.seeds:
        _seed_table(args.seeds)
    print(f"{'clip':24s}{'reference':14s}" + "".join(f"{h:>10s}" for _, h in COLUMNS) + "  reason")
    kinds = [*REFERENCES, *(["feasible+res"] if args.residual_iterations else [])]
    valid = {k: [] for k in kinds}
    with tempfile.TemporaryDirectory() as tmp:
        for name, human in _clips():
            robot, _, _ = retarget_clip(human)
            for kind in kinds:
                if kind == "feasible+res":
                    ckpt = train_residual(robot, args.residual_iterations, 16, 0, Path(tmp) / "residual.pt")
                _, _, f, _ = physicalize_clip(robot, **({"teacher": f"base+residual:{ckpt}"} if kind == "feasible+res" else {"reference": kind}))
                valid[kind].append(f["valid"])
                print(f"{name:24s}{kind:14s}" + "".join(f"{_cell(k, f):>10s}" for k, _ in COLUMNS) + f"  {f['reason'][:60]}", flush=True)
    for kind, v in valid.items():
        print(f"valid fraction ({kind}): {sum(v)}/{len(v)} = {sum(v) / max(len(v), 1):.2f}")


if __name__ == "__main__":
    main()
