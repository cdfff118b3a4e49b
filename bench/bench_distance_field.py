"""Speed and accuracy of the distance fields (:mod:`pipeline.distance.field`), per CPU-second, one thread.

    python bench/bench_distance_field.py [--points 1000000] [--mesh-points 300000] [--repeat 3]
                                         [--mesh ../shared/mocap/intermimic/largetable_largetable.obj]

Primitives: ``ObjectField.query`` on random points around each object at a random pose (one
pose; and as frames x links, 20 links, a pose per frame), numpy, exact. Chair too.

Mesh: the scan with its largest faces split in four until it has 50,001 faces (same surface),
or an icosphere when the scan is absent. Rows: the exact warp BVH query, the cached octree
field, and trimesh's exact ``closest_point`` (needs the ``rtree`` package; without it,
``closest_point_naive``, brute force) as the baseline, on three point sets: near the surface
(surface samples + N(0, sigma), sigma ~ U(0, 6 cm)), uniform in the bounds + 1 m, and a
hand-like approach (20 links on lines toward surface points, 50k frames, a pose per frame).
Errors are against the exact query: max/mean |phi| error within 0.1 m of the surface and
beyond, grad error |g - g_exact| (outside the solid, where it is defined without medial
jumps), and the share of points the cached field sent to the exact query.

Rates are points per CPU-second (``time.process_time``), best of ``--repeat``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import trimesh  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from pipeline.distance.field import ObjectField  # noqa: E402
from pipeline.distance.mesh import MeshShape, _numpy_exact  # noqa: E402
from pipeline.distance.octree import CachedField, OctreeSpec  # noqa: E402
from pipeline.geometry import Chair, Primitive  # noqa: E402

RNG = np.random.default_rng(0)
SCAN = Path(__file__).resolve().parents[2] / "shared" / "mocap" / "intermimic" / "largetable_largetable.obj"


def rate(fn, n: int, repeat: int) -> float:
    best = 0.0
    for _ in range(repeat):
        t = time.process_time()
        fn()
        best = max(best, n / max(time.process_time() - t, 1e-9))
    return best


def row(*cells) -> None:
    print(" | ".join(str(c) for c in cells))


def bench_primitives(n: int, repeat: int) -> None:
    pose = np.r_[0.3, -0.2, 0.8, Rotation.random(random_state=1).as_quat(scalar_first=True)]
    R = Rotation.from_quat(pose[3:], scalar_first=True).as_matrix()
    frames = n // 20
    poses = np.tile(pose, (frames, 1))
    cases = [
        ("box", Primitive("box", (0.3, 0.2, 0.1)), trimesh.creation.box((0.6, 0.4, 0.2))),
        ("sphere", Primitive("sphere", (0.2,)), trimesh.creation.icosphere(4, 0.2)),
        ("cylinder", Primitive("cylinder", (0.1, 0.3)), trimesh.creation.cylinder(0.1, 0.6, sections=64)),
        ("capsule", Primitive("capsule", (0.1, 0.2)), trimesh.creation.capsule(0.4, 0.1, count=[32, 32])),
        ("box scaled (1.6,0.4,1)", Primitive("box", (0.3, 0.2, 0.1), (1.6, 0.4, 1.0)), None),
        ("sphere scaled (1,1.5,0.5)", Primitive("sphere", (0.2,), (1.0, 1.5, 0.5)), None),
        ("cylinder scaled (2,1,0.7)", Primitive("cylinder", (0.1, 0.3), (2.0, 1.0, 0.7)), None),
        ("capsule scaled (1,1,2)", Primitive("capsule", (0.1, 0.2), (1.0, 1.0, 2.0)), None),
        ("capsule scaled (2,1.5,0.6)", Primitive("capsule", (0.1, 0.2), (2.0, 1.5, 0.6)), None),
        ("chair (6 boxes)", Chair(), None),
    ]
    print(f"\n## Primitives, exact, numpy, {n:,} points (random pose)\n")
    row("object", "query M/s", "frames x 20 links M/s", "trimesh closest_point (mesh of it) M/s")
    row("---", "---", "---", "---")
    for name, geom, mesh in cases:
        field = ObjectField.from_geometry(geom)
        local = RNG.uniform(-0.6, 0.6, (n, 3))
        world = local @ R.T + pose[:3]
        q = rate(lambda: field.query(world, pose), n, repeat)
        links = world[: frames * 20].reshape(frames, 20, 3)
        ql = rate(lambda: field.query_links(links, poses), frames * 20, repeat)
        base = "-"
        if mesh is not None:
            m = 2000
            base = f"{rate(lambda: _trimesh(mesh, local[:m]), m, 1) / 1e6:.4f}"
        row(name, f"{q / 1e6:.2f}", f"{ql / 1e6:.2f}", base)


def _trimesh(mesh, p):
    try:
        import rtree  # noqa: F401
    except ImportError:
        return trimesh.proximity.closest_point_naive(mesh, p)
    return trimesh.proximity.closest_point(mesh, p)


def mesh_50k(path: Path | None) -> trimesh.Trimesh:
    """The scan with its largest faces split in four up to 50,001 faces, or a subdivided icosphere."""
    if path is not None and path.is_file():
        m = trimesh.load(path, force="mesh", process=False)
        extra = max(0, (50_001 - len(m.faces)) // 3)
        v, f = trimesh.remesh.subdivide(m.vertices, m.faces, face_index=np.argsort(-m.area_faces)[:extra])
        return trimesh.Trimesh(v, f, process=False)
    m = trimesh.creation.icosphere(subdivisions=6, radius=0.3)  # 81,920 faces
    return trimesh.Trimesh(m.vertices * [1.0, 0.8, 0.6], m.faces, process=False)


def _approach(mesh: trimesh.Trimesh, frames: int, links: int = 20) -> np.ndarray:
    """Links moving on straight lines from 0.6 m out onto surface points (frames, links, 3)."""
    target = mesh.sample(links, seed=2)
    start = target + RNG.normal(size=(links, 3)) * 0.35
    s = np.linspace(0.0, 1.0, frames)[:, None, None] ** 0.5
    return start[None] + s * (target - start)[None] + RNG.normal(size=(frames, links, 3)) * 1e-3


def bench_mesh(path: Path | None, n: int, repeat: int) -> None:
    mesh = mesh_50k(path)
    shape = MeshShape(str(path), np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int32))
    spec = OctreeSpec()
    t = time.process_time()
    tree = CachedField.build(lambda p: _numpy_exact(shape, p), mesh.bounds[0], mesh.bounds[1], spec)
    build = time.process_time() - t
    cached = MeshShape(shape.path, shape.vertices, shape.faces, tree, spec.tol_near)
    print(f"\n## Mesh: {path.name if path else 'icosphere'} ({len(mesh.faces):,} faces), cached field {spec}\n")
    print(f"build {build:.1f} CPU-s, {tree.stats()}\n")
    near = mesh.sample(n, seed=1) + RNG.normal(size=(n, 3)) * RNG.uniform(0, 0.06, (n, 1))
    box = RNG.uniform(mesh.bounds[0] - 1.0, mesh.bounds[1] + 1.0, (n, 3))
    frames = n // 20
    links = _approach(mesh, frames).reshape(-1, 3)
    row(
        "points",
        "method",
        "M points/CPU-s",
        "exact share",
        "phi err <=0.1 m max / mean (mm)",
        "phi err >0.1 m max / mean (mm)",
        "grad err outside p50 / p99 / max",
    )
    row(*["---"] * 7)
    for name, p in [("near surface", near), ("bounds + 1 m", box), ("20 links x frames", links)]:
        e_phi, e_grad, e_c = _numpy_exact(shape, p)
        outside = ((p - e_c) * e_grad).sum(1) >= 0
        band = e_phi <= 0.1
        row(
            name,
            "warp exact (BVH)",
            f"{rate(lambda: shape.exact(p, np), len(p), repeat) / 1e6:.2f}",
            "1.00",
            "0 / 0",
            "0 / 0",
            "0",
        )
        phi, g, _, used = cached.detail(p, np)
        g = np.stack(g, 1)
        err = np.abs(phi - e_phi) * 1e3
        gerr = np.linalg.norm(g - e_grad, axis=1)[outside]
        b = f"{err[band].max():.3f} / {err[band].mean():.4f}" if band.any() else "-"
        f = f"{err[~band].max():.3f} / {err[~band].mean():.4f}" if (~band).any() else "-"
        gq = f"{np.median(gerr):.4f} / {np.quantile(gerr, 0.99):.3f} / {gerr.max():.2f}"
        row(
            name,
            "cached octree",
            f"{rate(lambda: cached.detail(p, np), len(p), repeat) / 1e6:.2f}",
            f"{used.mean():.3f}",
            b,
            f,
            gq,
        )
        m = 300
        row(
            name,
            "trimesh closest_point" + ("" if _has_rtree() else "_naive (no rtree)"),
            f"{rate(lambda: _trimesh(mesh, p[:m]), m, 1) / 1e6:.4f}",
            "-",
            "-",
            "-",
            "-",
        )
    field = ObjectField(cached, "mesh")
    poses = np.tile(np.r_[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (frames, 1))
    lk = links.reshape(frames, 20, 3)
    print(
        "\nObjectField.query_links (pose per frame, numpy in/out) on the approach: "
        f"{rate(lambda: field.query_links(lk, poses), len(links), repeat) / 1e6:.2f} M link-queries/CPU-s"
    )


def _has_rtree() -> bool:
    try:
        import rtree  # noqa: F401
    except ImportError:
        return False
    return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--mesh-points", type=int, default=300_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--mesh", type=Path, default=SCAN)
    ap.add_argument("--skip-primitives", action="store_true")
    a = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    if not a.skip_primitives:
        bench_primitives(a.points, a.repeat)
    bench_mesh(a.mesh if a.mesh.is_file() else None, a.mesh_points, a.repeat)


if __name__ == "__main__":
    main()
