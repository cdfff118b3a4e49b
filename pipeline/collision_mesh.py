"""Collision shapes for mesh objects: one convex hull, or a convex decomposition (CoACD).

MuJoCo collides meshes through their convex hulls, so a concave object (a table, a
chair) needs several convex pieces to be seen right by the physics. Real scans such
as OMOMO's box are not watertight; both routes only need the surface:

* ``hull`` -- ``trimesh``'s convex hull of the vertices (exact for convex objects);
* ``decomposition`` -- CoACD (collision-aware approximate convex decomposition,
  concavity threshold 0.05, seed 0, at most 16 parts). It takes seconds to tens of
  seconds per mesh, so pieces are cached on disk, keyed by the file's SHA-256 and the
  parameters, under ``$LESSMIMIC_CACHE`` (default ``~/.cache/lessmimic``).

The visual model is always the original mesh.
"""

from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path

import numpy as np
import trimesh

from pipeline.errors import InputError
from pipeline.geometry import MeshGeometry

COACD_THRESHOLD = 0.05
COACD_MAX_PARTS = 16


def cache_dir() -> Path:
    return Path(os.environ.get("LESSMIMIC_CACHE", Path.home() / ".cache" / "lessmimic"))


@lru_cache(maxsize=32)
def load_mesh(path: str) -> trimesh.Trimesh:
    """The mesh file as one triangle mesh (scenes concatenated); missing or empty -> InputError."""
    p = Path(path)
    if p.is_dir():
        raise InputError(p, "mesh", "is a folder; give the object's mesh file (.obj, .stl, .ply)")
    if not p.is_file():
        raise InputError(p, "mesh", "object mesh file not found")
    try:
        mesh = trimesh.load(p, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise InputError(p, "mesh", f"cannot be read as a mesh ({type(exc).__name__}: {exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(p, "mesh", "object mesh is empty (no faces)")
    if len(mesh.vertices) < 4:
        raise InputError(
            p, "mesh", f"has {len(mesh.vertices)} vertices: too few to enclose a volume (an object needs at least 4)"
        )
    if not np.isfinite(mesh.vertices).all():
        raise InputError(p, "mesh vertices", "contain NaN or infinite values")
    return mesh


def check_meshes(clips) -> None:
    """Every object mesh the clips (human or robot) name loads (:func:`load_mesh`): a stage calls it on its input
    before any work, so a folder, a missing or a degenerate mesh is its one line before the work, not after."""
    from pipeline.geometry import MeshGeometry

    for path in dict.fromkeys(
        o.geometry.path for c in clips for o in c.objects if isinstance(o.geometry, MeshGeometry)
    ):
        load_mesh(path)


def _file_digest(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def collision_parts(geom: MeshGeometry) -> list[trimesh.Trimesh]:
    """Convex pieces (in the mesh's unscaled frame) that the physics uses for ``geom``."""
    mesh = load_mesh(geom.path)
    if geom.collision == "hull":
        return [mesh.convex_hull]
    key = f"coacd-{_file_digest(geom.path)}-t{COACD_THRESHOLD}-n{COACD_MAX_PARTS}.npz"
    cached = cache_dir() / key
    if cached.is_file():
        with np.load(cached) as z:
            return [trimesh.Trimesh(z[f"v{i}"], z[f"f{i}"], process=False) for i in range(int(z["n"]))]
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(mesh.vertices, mesh.faces), threshold=COACD_THRESHOLD, max_convex_hull=COACD_MAX_PARTS, seed=0
    )
    hulls = [trimesh.Trimesh(v, f, process=False).convex_hull for v, f in parts]
    cached.parent.mkdir(parents=True, exist_ok=True)
    tmp = cached.with_suffix(f".{os.getpid()}.tmp.npz")
    arrays = {"n": np.array(len(hulls))}
    for i, h in enumerate(hulls):
        arrays[f"v{i}"], arrays[f"f{i}"] = h.vertices, h.faces
    np.savez(tmp, **arrays)
    os.replace(tmp, cached)
    return hulls
