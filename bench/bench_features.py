"""``make bench-features``: the distance fields against trimesh's exact closest point, and the whole features
stage on the embedded default, in one run.

    python bench/bench_features.py [--points 1000000] [--mesh-points 300000] [--repeat 3] [--name bench-features]

1. The distance-field table of ``bench/bench_distance_field.py`` (primitives exact; the 50k-face
   table scan: warp exact, cached octree, trimesh baseline; link-queries per CPU-second, errors).
2. The features stage (``lessmimic features``) on ``datasets/<NAME>/physicalized/``; when that dataset is
   missing it is made first from the embedded default (``retarget``, then ``physicalize --keep-invalid``:
   the benchmark measures the features, not the validity, and takes a few minutes). Printed: frames,
   frames per CPU-second and link-queries per CPU-second per clip and in total (from the stage's report).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_distance_field import SCAN, bench_mesh, bench_primitives  # noqa: E402


def bench_stage(name: str) -> None:
    from lessmimic.cli import main as cli
    from pipeline.stage.paths import stage_dir

    if not (stage_dir(name, "retargeted") / "meta" / "info.json").is_file():
        assert cli(["retarget", "--name", name]) == 0
    if not (stage_dir(name, "physicalized") / "meta" / "info.json").is_file():
        assert cli(["physicalize", "--name", name, "--keep-invalid", "--overwrite"]) == 0
    t0 = time.perf_counter()
    assert cli(["features", "--name", name, "--overwrite"]) == 0
    wall = time.perf_counter() - t0
    import json

    report = json.loads((stage_dir(name, "features") / "report.json").read_text())
    print(
        f"\n## features stage on datasets/{name}/physicalized ({report['summary']['clips']} clips), per CPU-second, "
        "one process"
    )
    print("| clip | frames | frames/s | link-queries/s | min phi (m) |")
    print("|---|---|---|---|---|")
    for c in report["clips"]:
        print(
            f"| {c['source']} | {c['frames']} | {c['frames_per_cpu_s']:.0f} | {c['link_queries_per_cpu_s'] / 1e3:.0f}k "
            f"| {c['phi_min_m']:.3f} |"
        )
    s = report["summary"]
    print(f"| total | {s['frames']} | {s['frames_per_cpu_s']:.0f} | | |")
    print(f"loading the objects' fields (meshes, warp), once per geometry: {s['fields_setup_cpu_s']:.1f} CPU-s")
    print(f"whole command (read, compute, write LeRobot dataset, plots): {wall:.1f} s wall for {s['frames']} frames")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--mesh-points", type=int, default=300_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument(
        "--name", default="bench-features", help="dataset name (made from the embedded default when missing)"
    )
    a = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    bench_primitives(a.points, a.repeat)
    bench_mesh(SCAN if SCAN.is_file() else None, a.mesh_points, a.repeat)
    bench_stage(a.name)


if __name__ == "__main__":
    main()
