"""Distance fields of objects at a pose: phi, grad and closest point for humanoid links (paper Sec. III-A).

For an object with surface S and world pose (t, R) (``pose = (x, y, z, qw, qx, qy, qz)``), a
world point x is taken into the object frame, p = R^T (x - t), the object-frame field gives
phi(p), grad(p) and the closest surface point c(p), and the results go back to the world:

    phi(x) = phi(p),    grad(x) = R grad(p),    closest(x) = R c(p) + t,

with phi = min_{c in S} |x - c| (unsigned) and grad = (x - c)/phi, or the outward surface normal
at c on the surface and inside the solid (see :mod:`pipeline.distance.primitive`). Several
objects: each point takes the nearest object (:class:`ObjectFields`), first object on ties.

Every query runs on numpy arrays or torch tensors (CPU or CUDA), with the same math; inputs are
processed in chunks of :data:`CHUNK` points so the working set stays in cache. A shape with a
``world(points, R, t)`` method (the box, the chair, the scaled sphere, cylinder, capsule) does the pose in its warp
kernel for numpy points at one pose or at one pose per frame (:meth:`ObjectField.query_links`):
same math, no numpy per-point pass; it returns None to decline. Per-point poses take the numpy pass.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from pipeline.distance.primitive import chair_shape, primitive_shape
from pipeline.errors import InputError, first_bad_frame
from pipeline.geometry import Chair, MeshGeometry, ObjectGeometry, Primitive, geometry_from_dict
from pipeline.rotations import rotation_rows
from pipeline.xp import as_float, namespace, to_numpy

CHUNK = 32768


class FieldSample(NamedTuple):
    """phi (...,), grad (..., 3) unit, closest (..., 3) world surface point."""

    phi: Any
    grad: Any
    closest: Any


class NearestSample(NamedTuple):
    """As :class:`FieldSample`, with the index of the nearest object."""

    phi: Any
    grad: Any
    closest: Any
    object_index: Any


def _rigid(pose) -> tuple[list, tuple]:
    """(t, rows of R) as floats for one pose (7,)."""
    p = [float(v) for v in pose]
    R = rotation_rows(np.asarray(p[3:]), np)
    return p[:3], tuple(tuple(float(v) for v in row) for row in R)


def _check(name: str, field: str, a, shape: tuple, xp) -> None:
    """``a`` must have ``shape`` (None = any length) and finite values, else a one-line InputError."""
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise InputError(None, f"{name} {field}", f"expected shape {want}, got {tuple(a.shape)}")
    bad = ~xp.isfinite(a)
    if bool(bad.any()):
        raise InputError(None, f"{name} {field}", f"non-finite value at row {first_bad_frame(to_numpy(bad))}")


def _check_quaternion(name: str, field: str, pose, xp) -> None:
    q = pose[..., 3:]
    bad = (q * q).sum(-1) < 1e-12
    if bool(bad.any()):
        row = "" if pose.ndim == 1 else f" at row {first_bad_frame(to_numpy(bad))}"
        raise InputError(None, f"{name} {field}", f"quaternion (qw, qx, qy, qz) is zero{row}")


@dataclass(frozen=True)
class ObjectField:
    """The distance field of one object; ``shape.local(x, y, z, xp)`` is its object-frame field."""

    shape: Any
    name: str = "object"

    @classmethod
    def from_geometry(cls, geom: ObjectGeometry | dict, name: str = "object", **mesh_options) -> ObjectField:
        """Field of a Primitive, Chair or MeshGeometry (or its :func:`geometry_to_dict` form).
        ``mesh_options`` go to :class:`pipeline.distance.mesh.MeshShape` (e.g. ``cache=False``)."""
        if isinstance(geom, dict):
            try:
                geom = geometry_from_dict(geom)
            except (ValueError, KeyError, TypeError) as exc:
                raise InputError(None, f"{name} geometry", str(exc)) from None
        if isinstance(geom, Primitive):
            return cls(primitive_shape(geom), name)
        if isinstance(geom, Chair):
            return cls(chair_shape(geom), name)
        if isinstance(geom, MeshGeometry):
            from pipeline.distance.mesh import MeshShape

            return cls(MeshShape.from_geometry(geom, **mesh_options), name)
        raise InputError(
            None, f"{name} geometry", f"expected Primitive, Chair or MeshGeometry, got {type(geom).__name__}"
        )

    def query(self, points, pose) -> FieldSample:
        """phi (N,), grad (N, 3), closest (N, 3) at world ``points`` (N, 3) for ``pose`` (7,) or per-point (N, 7)."""
        xp = namespace(points)
        points = as_float(points, xp)
        pose = as_float(pose, xp, like=points)
        _check(self.name, "points", points, (None, 3), xp)
        _check(self.name, "pose", pose, (7,) if pose.ndim == 1 else (len(points), 7), xp)
        _check_quaternion(self.name, "pose", pose, xp)
        return self._run(points, pose, xp)

    def query_links(self, points, poses) -> FieldSample:
        """Links over frames: ``points`` (T, K, 3) with object ``poses`` (T, 7) -> phi (T, K), grad/closest (T, K,
        3)."""
        xp = namespace(points)
        points = as_float(points, xp)
        poses = as_float(poses, xp, like=points)
        _check(self.name, "link points", points, (None, None, 3), xp)
        _check(self.name, "poses", poses, (points.shape[0], 7), xp)
        _check_quaternion(self.name, "poses", poses, xp)
        return self._run(points, poses[:, None, :], xp)

    def _run(self, points, pose, xp) -> FieldSample:
        """``pose`` (7,) for all points, (N, 7) per point, or (T, 1, 7) per frame of ``points`` (T, K, 3)."""
        if xp is np and pose.ndim != 2 and hasattr(self.shape, "world"):  # pose and field fused in one kernel
            fused = self._fused(points, pose.reshape(-1, 7))
            if fused is not None:
                return fused
        lead = points.shape[:-1]
        phi = (
            xp.zeros(lead, dtype=points.dtype) if xp is np else xp.zeros(lead, dtype=points.dtype, device=points.device)
        )
        grad, closest = 0.0 * points, 0.0 * points
        if pose.ndim == 1 and xp is not np:  # one pose: plain scalars broadcast fastest
            pose = pose.tolist()
        rows = max(1, CHUNK // max(1, int(np.prod(lead[1:]))))
        for i in range(0, lead[0] if lead else 0, rows):
            sl = slice(i, i + rows)
            pz = pose if isinstance(pose, list) or pose.ndim == 1 else pose[sl]
            phi[sl], grad[sl], closest[sl] = self._chunk(points[sl], pz, xp)
        return FieldSample(phi, grad, closest)

    def _fused(self, points, poses) -> FieldSample | None:
        """The shape's warp kernel for numpy ``points`` (T, K, 3) or (N, 3) at ``poses`` (T, 7), or None."""
        R = np.stack([np.stack(row, -1) for row in rotation_rows(poses[:, 3:], np)], -2)
        out = self.shape.world(points.reshape(-1, 3), R, poses[:, :3])
        if out is None:
            return None
        lead = points.shape[:-1]
        return FieldSample(out[0].reshape(lead), out[1].reshape(*lead, 3), out[2].reshape(*lead, 3))

    def _chunk(self, pts, pose, xp):
        if isinstance(pose, list) or pose.ndim == 1:
            t, R = _rigid(pose)
        else:
            t, R = (pose[..., 0], pose[..., 1], pose[..., 2]), rotation_rows(pose[..., 3:], xp)
        X, Y, Z = pts[..., 0] - t[0], pts[..., 1] - t[1], pts[..., 2] - t[2]
        local = [R[0][j] * X + R[1][j] * Y + R[2][j] * Z for j in range(3)]
        shape = local[0].shape
        phi, g, c = self.shape.local(*(a.reshape(-1) for a in local), xp)
        g = [a.reshape(shape) for a in g]
        c = [a.reshape(shape) for a in c]
        grad = xp.stack([R[i][0] * g[0] + R[i][1] * g[1] + R[i][2] * g[2] for i in range(3)], -1)
        closest = xp.stack([R[i][0] * c[0] + R[i][1] * c[1] + R[i][2] * c[2] + t[i] for i in range(3)], -1)
        return phi.reshape(shape), grad, closest


@dataclass(frozen=True)
class ObjectFields:
    """Several objects; each point takes the nearest (the first on ties) and reports its index."""

    objects: tuple[ObjectField, ...]

    def query(self, points, poses) -> NearestSample:
        """``points`` (N, 3); ``poses`` (M, 7) one per object, or (M, N, 7) per object and point."""
        if len(poses) != len(self.objects):
            raise InputError(
                None, "object poses", f"expected {len(self.objects)} poses (one per object), got {len(poses)}"
            )
        return self._nearest([o.query(points, poses[m]) for m, o in enumerate(self.objects)], namespace(points))

    def query_links(self, points, poses) -> NearestSample:
        """``points`` (T, K, 3), ``poses`` (T, M, 7) -> phi, object_index (T, K); grad, closest (T, K, 3)."""
        xp = namespace(points)
        if poses.ndim != 3 or poses.shape[1] != len(self.objects):
            raise InputError(
                None, "object poses", f"expected shape (T, {len(self.objects)}, 7), got {tuple(poses.shape)}"
            )
        return self._nearest([o.query_links(points, poses[:, m]) for m, o in enumerate(self.objects)], xp)

    @staticmethod
    def _nearest(samples: list[FieldSample], xp) -> NearestSample:
        phi, grad, closest = samples[0]
        index = 0 * phi.astype(np.int64) if xp is np else 0 * phi.long()
        for m, s in enumerate(samples[1:], start=1):
            near = s.phi < phi
            phi = xp.where(near, s.phi, phi)
            grad = xp.where(near[..., None], s.grad, grad)
            closest = xp.where(near[..., None], s.closest, closest)
            index = xp.where(near, m, index)
        return NearestSample(phi, grad, closest, index)


def boxes_query_links(points, poses, half, centre=None) -> tuple[Any, Any]:
    """``(phi (N, K), grad (N, K, 3))`` of N boxes of their own half-extents ``half`` (N, 3), each at its pose
    ``poses`` (N, 7), for their K points ``points`` (N, K, 3): one batch where each box size would otherwise be its
    own :class:`ObjectField` (a post-training episode draws its own scale). With ``half`` (N, P, 3) and the parts'
    ``centre`` (N, P, 3) in the object frame, N unions of P boxes (chairs), each point taking its nearest part (the
    first on ties), as :class:`pipeline.distance.primitive.ChairShape`. The pose transform is
    :meth:`ObjectField._chunk`'s, the field :func:`pipeline.distance.primitive.box_local`; numpy or torch alike (the
    CPU environment and the mjlab backend share it)."""
    from pipeline.distance.primitive import box_local, nearest_box

    xp = namespace(points)
    local, R = _object_frame(points, poses, xp)
    if half.ndim == 2:
        phi, g, _ = box_local(*local, half[:, None, 0], half[:, None, 1], half[:, None, 2], xp)
    else:
        parts = [([half[:, None, k, i] for i in range(3)], [centre[:, None, k, i] for i in range(3)])
                 for k in range(half.shape[1])]  # fmt: skip
        part = nearest_box(*local, parts, xp)
        rows = xp.arange(len(half))[:, None] if xp is np else xp.arange(len(half), device=half.device)[:, None]
        h, c = half[rows, part], centre[rows, part]
        phi, g, _ = box_local(*(local[i] - c[..., i] for i in range(3)), *(h[..., i] for i in range(3)), xp)
    return phi, _world_vectors(g, R, xp)


def cylinders_query_links(points, poses, radius, half_length) -> tuple[Any, Any]:
    """:func:`boxes_query_links` for N circular cylinders along their z, each of its own ``radius`` and
    ``half_length`` (N,) (:func:`pipeline.distance.primitive.cylinder_local`); numpy or torch alike."""
    from pipeline.distance.primitive import cylinder_local

    xp = namespace(points)
    local, R = _object_frame(points, poses, xp)
    phi, g, _ = cylinder_local(*local, radius[:, None], half_length[:, None], xp)
    return phi, _world_vectors(g, R, xp)


def _object_frame(points, poses, xp) -> tuple[list, tuple]:
    """N objects' K points (N, K, 3) in their frames (poses (N, 7)), as three (N, K) coordinates, and the rows of
    each object's rotation (:meth:`ObjectField._chunk`'s transform)."""
    t = [poses[:, None, i] for i in range(3)]
    R = rotation_rows(poses[:, None, 3:7], xp)
    X, Y, Z = points[..., 0] - t[0], points[..., 1] - t[1], points[..., 2] - t[2]
    return [R[0][j] * X + R[1][j] * Y + R[2][j] * Z for j in range(3)], R


def _world_vectors(g, R, xp):
    """Object-frame vectors ``g`` (three (N, K) components) turned to the world, (N, K, 3)."""
    return xp.stack([R[i][0] * g[0] + R[i][1] * g[1] + R[i][2] * g[2] for i in range(3)], -1)
