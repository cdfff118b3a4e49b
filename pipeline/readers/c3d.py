"""C3D marker trajectories (via ``ezc3d``) -> :class:`HumanClip` whose "joints" are the markers.

* Markers: the first ``POINT:USED`` labels of ``POINT:LABELS`` (+ ``LABELS2``...), stripped;
  an empty label becomes ``marker<k>``, a repeated one gets ``#2``, ``#3``. The skeleton is
  flat (every parent ``-1``): mapping markers to anatomical joints is left to the retargeter,
  and markers on props (here the ``boite:`` box markers) are kept like any other.
* Units: ``POINT:UNITS`` (``mm``, ``cm``, ``m``; C3D's default ``mm`` when absent) -> metres.
* Gaps: a sample is missing when its residual is negative, a coordinate is NaN, or all three
  coordinates are exactly 0 (some writers' convention). Gaps of at most ``max_gap`` seconds
  are filled by linear interpolation between the neighbouring samples (leading/trailing gaps
  hold the nearest sample). Longer gaps follow ``long_gaps``: ``"interpolate"`` (default: the
  same fill, with a ``UserWarning`` naming the marker and frames), ``"drop"`` (the marker is
  removed, with a warning) or ``"error"`` (:class:`InputError` naming marker and frames).
  A marker with no valid sample at all is always an :class:`InputError`.
* Up axis: ``up="auto"`` reads ``POINT:Y_SCREEN`` (the axis drawn upward): ``+Y`` means
  y-up (rotated to z-up by :data:`~pipeline.rotations.Y_UP_TO_Z_UP`), anything else z-up,
  which is most labs' convention. ``up="y"``/``"z"`` override it.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from pipeline.clip import HumanClip, Skeleton
from pipeline.errors import InputError
from pipeline.foot_contact import runs
from pipeline.readers.keypoints import UNIT_SCALE, up_matrix
from pipeline.suspicious import suspect

_UNITS = {"mm": "mm", "millimeters": "mm", "cm": "cm", "m": "m", "meters": "m"}


def _param(c, group: str, name: str, default=None):
    p = c["parameters"].get(group, {}).get(name)
    return default if p is None else p["value"]


def _header_frames(path: str | Path) -> int | None:
    """Frame count from the C3D header words 4-5 (first/last frame), or None if unreadable."""
    with open(path, "rb") as f:
        head = f.read(512)
        if len(head) < 10 or head[1] != 0x50:
            return None
        f.seek((head[0] - 1) * 512 + 3)
        proc = f.read(1)
    order = ">" if proc and proc[0] == 86 else "<"  # 84 Intel, 85 DEC (little-endian words), 86 MIPS
    first, last = struct.unpack(order + "HH", head[6:10])
    return last - first + 1


def _labels(c, n: int) -> list[str]:
    raw: list[str] = []
    for key in ["LABELS"] + [f"LABELS{k}" for k in range(2, 10)]:
        raw += list(_param(c, "POINT", key, []) or [])
    out: list[str] = []
    for k in range(n):
        base = (raw[k].strip() if k < len(raw) else "") or f"marker{k}"
        name, rep = base, 2
        while name in out:
            name, rep = f"{base}#{rep}", rep + 1
        out.append(name)
    return out


def _up(c, up: str, src: str) -> str:
    if up in ("y", "z"):
        return up
    if up != "auto":
        raise InputError(src, "up", f"unknown up axis {up!r}; use 'auto', 'y' or 'z'")
    screen = (_param(c, "POINT", "Y_SCREEN", [""]) or [""])[0].strip().upper()
    return "y" if screen in ("+Y", "Y") else "z"


def fill_gaps(xyz: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """Linear interpolation over missing frames of one ``[T, 3]`` track (edges hold)."""
    t = np.arange(len(xyz))
    ok = ~missing
    return np.stack([np.interp(t, t[ok], xyz[ok, k]) for k in range(3)], axis=1)


def read_c3d(path: str | Path, *, up: str = "auto", max_gap: float = 0.25, long_gaps: str = "interpolate") -> HumanClip:
    """A C3D file's labelled markers as a z-up metre :class:`HumanClip` (see the module doc)."""
    import ezc3d

    src = str(path)
    if long_gaps not in ("interpolate", "drop", "error"):
        raise InputError(src, "long_gaps", f"{long_gaps!r} is not 'interpolate', 'drop' or 'error'")
    try:
        frames = _header_frames(path)
        c = None if frames == 0 else ezc3d.c3d(str(path))
    except OSError as e:
        raise InputError(src, "file", f"cannot read: {e.strerror or e}") from None
    except (RuntimeError, ValueError, IndexError) as e:
        raise InputError(src, "file", f"not a readable C3D file ({e})") from None
    if c is None:
        raise InputError(src, "frames", "has zero frames (header first/last frame)")
    pts = np.asarray(c["data"]["points"], dtype=np.float64)  # (4, M, T)
    if pts.ndim != 3 or pts.shape[1] == 0:
        raise InputError(src, "POINT:USED", "the file has no 3-D markers")
    if pts.shape[2] == 0:
        raise InputError(src, "frames", "has zero frames")
    if frames is not None and pts.shape[2] < frames:  # ezc3d reads a cut file up to where it ends, without a word
        why = f"the header promises {frames} frames (first/last frame), the file holds {pts.shape[2]} (truncated?)"
        raise InputError(src, "frames", why, frame=pts.shape[2])
    fps = float(_param(c, "POINT", "RATE", [c["header"]["points"]["frame_rate"]])[0])
    unit_name = (_param(c, "POINT", "UNITS", ["mm"]) or ["mm"])[0].strip().lower()
    if unit_name not in _UNITS:
        raise InputError(src, "POINT:UNITS", f"unknown unit {unit_name!r} (expected mm, cm or m)")
    xyz = pts[:3].transpose(2, 1, 0).copy()  # (T, M, 3)
    resid = c["data"]["meta_points"]["residuals"][0].T if "meta_points" in c["data"] else np.zeros(xyz.shape[:2])
    missing = (resid < 0) | ~np.isfinite(xyz).all(axis=2) | (xyz == 0).all(axis=2)
    labels = _labels(c, xyz.shape[1])
    limit = max(int(round(max_gap * fps)), 0)
    keep, long_runs = [], []
    for m, name in enumerate(labels):
        miss = missing[:, m]
        if miss.all():
            raise InputError(src, f"marker {name}", "has no valid sample in any frame (all gap)")
        gaps = [(a, b) for a, b in runs(miss) if b - a > limit]
        if gaps and long_gaps == "error":
            a, b = gaps[0]
            raise InputError(
                src,
                f"marker {name}",
                f"gap of {b - a} frames ({a}-{b - 1}) is longer than max_gap {max_gap} s",
                frame=int(a),
            )
        long_runs += [f"{name} {a}-{b - 1}" for a, b in gaps]
        if gaps and long_gaps == "drop":
            continue
        if miss.any():
            xyz[:, m] = fill_gaps(xyz[:, m], miss)
        keep.append(m)
    if long_runs:
        what = "dropped markers with" if long_gaps == "drop" else "interpolated"
        suspect(src, "markers", f"{what} gaps longer than {max_gap} s: {', '.join(long_runs)}")
    if not keep:
        raise InputError(src, "markers", "every marker was dropped for long gaps")
    pos = xyz[:, keep] * UNIT_SCALE[_UNITS[unit_name]] @ up_matrix(_up(c, up, src), src).T
    names = tuple(labels[m] for m in keep)
    return HumanClip(Skeleton(names, (-1,) * len(names)), pos, fps, src)
