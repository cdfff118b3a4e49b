"""Retarget quality and speed, ours vs the OmniRetarget output of the same OMOMO clip, side by side.

Run: ``make bench-retarget`` (needs ``../shared/mocap``; clips that are missing are skipped).
Every row is measured by :func:`retarget.metrics.retarget_metrics` with OUR collision model.
``frames/s`` counts the robot's 50 Hz output frames over the whole clip (scene build, IK,
metrics; one process, one core, after one untimed warm-up clip; the best of ``REPEATS`` runs, since
this machine's other load makes single timings vary by +-30%); ``src frames/s`` counts the source's own frames.
OmniRetarget's speed is not re-measured here (0.36 frames/s measured elsewhere).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import torch

torch.set_num_threads(1)

from ingest.default_input import default_clips  # noqa: E402
from pipeline.readers import read_clips  # noqa: E402
from retarget.clip import retarget_clip  # noqa: E402
from retarget.metrics import evaluate_file  # noqa: E402

REPEATS = 3
SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "mocap"
COLUMNS = [
    ("object_penetration_frac_1cm", "obj>1cm"),
    ("object_penetration_max_m", "obj max"),
    ("ground_penetration_frac_1cm", "gnd>1cm"),
    ("float_frac_2cm", "float"),
    ("foot_slide_frac_1cm_per_frame", "slide"),
    ("foot_slide_speed_max_mps", "slide m/s"),
    ("contact_preservation_frac", "contact"),
    ("joint_limit_violation_frac", "limits"),
    ("max_joint_speed_radps", "max rad/s"),
    ("self_collision_frac", "self"),
    ("frames", "frames"),
]


def _fmt(v) -> str:
    if isinstance(v, float) and math.isnan(v):
        return "n/a"
    return f"{v:.3f}" if isinstance(v, float) else str(v)


def main() -> int:
    rows = []
    sources = []
    if SHARED.is_dir():
        sources += [
            SHARED / "omomo" / "sub3_largebox_003.pt",
            SHARED / "intermimic" / "sub2_largetable_000.pt",
            SHARED / "bvh" / "pymo_walk_120hz.bvh",
        ]
    clips = [read_clips(p)[0] for p in sources if p.is_file()] + default_clips()
    retarget_clip(default_clips(fps=30.0)[2])  # warm-up, untimed: MuJoCo's first G1 compile takes ~3 s per process
    for clip in clips:
        dt = math.inf
        for _ in range(REPEATS):  # deterministic: every run gives the same metrics
            t0 = time.perf_counter()
            _, m, _ = retarget_clip(clip)
            dt = min(dt, time.perf_counter() - t0)
        rows.append((Path(clip.source).name, "ours (mink)", m, f"{m['frames'] / dt:.0f}", f"{clip.frames / dt:.0f}"))
        if clip.source.endswith("sub3_largebox_003.pt"):
            peer = SHARED / "omniretarget" / "sub3_largebox_003_mj_w_obj.npz"
            pm = evaluate_file(peer, human_path=clip.source, object_mesh=SHARED / "omomo" / "largebox.obj")
            rows.append((Path(clip.source).name, "OmniRetarget", pm, "0.36 (elsewhere)", ""))
    head = ["clip", "method"] + [c[1] for c in COLUMNS] + ["frames/s", "src frames/s"]
    table = [head] + [[r[0], r[1]] + [_fmt(r[2][k]) for k, _ in COLUMNS] + [r[3], r[4]] for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    for k, row in enumerate(table):
        print("  ".join(cell.ljust(w) for cell, w in zip(row, widths)))
        if k == 0:
            print("  ".join("-" * w for w in widths))
    return 0


if __name__ == "__main__":
    sys.exit(main())
