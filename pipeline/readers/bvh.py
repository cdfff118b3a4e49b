"""BVH (Biovision hierarchy) of any skeleton -> :class:`HumanClip` (z-up, metres).

Conventions, as read here:

* Each ``CHANNELS`` list is applied in the listed order. Rotation channels compose as
  intrinsic rotations, ``R_local = R_c1 @ R_c2 @ R_c3`` (``Zrotation Yrotation Xrotation``
  gives ``Rz Ry Rx``), angles in degrees; scipy's upper-case ``from_euler`` is exactly this.
* Position channels (on any joint) replace the matching ``OFFSET`` component; the other
  components keep the offset. LAFAN1 and most exporters write absolute root positions.
* Forward kinematics: ``R_g[j] = R_g[p] R_local[j]``, ``p_g[j] = p_g[p] + R_g[p] t[j]``,
  vectorised over frames (one pass over joints).
* ``End Site`` blocks are not joints of the returned skeleton (they carry no channels);
  their positions are used only for the height estimate (a head-top site helps).
* Output: positions ``s A p_g`` and orientations ``A R_g`` (wxyz), where ``A`` rotates the
  file's up axis to z (:func:`~pipeline.readers.keypoints.up_matrix`) and ``s`` is metres per
  unit. The joint frames themselves are the file's bone frames (not re-aligned).
* ``up="auto"``: the axis (y or z) along which the head joint sits farthest from the feet,
  averaged over frames (see :func:`guess_up`).
* Height: the rest pose (offsets, zero rotations) when it stands upright (its up extent is at
  least 3/4 of its widest horizontal extent, as in a T-pose), else the head-to-ankle bone path
  (:func:`~pipeline.body_height.estimate_height`). ``units="auto"`` picks the unit that
  makes that height closest to 1.7 m.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.body_height import estimate_height, plausible_height
from pipeline.clip import HumanClip, Skeleton
from pipeline.errors import InputError
from pipeline.readers.keypoints import guess_units, unit_scale, up_matrix
from pipeline.rotations import wxyz_from_rotation
from pipeline.suspicious import suspect

_AXES = {"X": 0, "Y": 1, "Z": 2}


@dataclass
class _Node:
    name: str
    parent: int
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    channels: list[str] = field(default_factory=list)
    end_site: bool = False


@dataclass
class BvhData:
    """The parsed file: joints (End Sites flagged), motion ``[T, C]`` and frame time."""

    nodes: list[_Node]
    motion: np.ndarray
    frame_time: float

    @property
    def joints(self) -> list[int]:
        return [i for i, n in enumerate(self.nodes) if not n.end_site]


def _parse_hierarchy(lines: list[str], src: str) -> tuple[list[_Node], int]:
    """Nodes in file order (parents first) and the index of the ``MOTION`` line."""
    nodes: list[_Node] = []
    stack: list[int] = []
    for ln, raw in enumerate(lines):
        tok = raw.split()
        if not tok or tok[0] in ("HIERARCHY", "{"):
            continue
        key = tok[0].upper()
        where = f"HIERARCHY line {ln + 1}"
        if key in ("ROOT", "JOINT"):
            if len(tok) < 2:
                raise InputError(src, where, f"{tok[0]} without a name")
            nodes.append(_Node(" ".join(tok[1:]), stack[-1] if stack else -1))
            stack.append(len(nodes) - 1)
        elif key == "END":
            if not stack:
                raise InputError(src, where, "End Site outside a joint")
            nodes.append(_Node(f"{nodes[stack[-1]].name}_end", stack[-1], end_site=True))
            stack.append(len(nodes) - 1)
        elif key == "}":
            if not stack:
                raise InputError(src, where, "unbalanced '}'")
            stack.pop()
        elif key == "OFFSET":
            if not stack or len(tok) != 4:
                raise InputError(src, where, "OFFSET needs 3 numbers inside a joint")
            nodes[stack[-1]].offset = _floats(tok[1:], src, where)
        elif key == "CHANNELS":
            chans = tok[2:]
            if not stack or len(tok) < 2 or not tok[1].isdigit() or int(tok[1]) != len(chans):
                raise InputError(src, where, "CHANNELS count does not match the channel names")
            for c in chans:
                if len(c) != 9 or c[0].upper() not in _AXES or c[1:].lower() not in ("rotation", "position"):
                    raise InputError(src, where, f"unknown channel {c!r}")
            nodes[stack[-1]].channels = [c[0].upper() + c[1:].lower() for c in chans]
        elif key == "MOTION":
            if stack or not nodes:
                raise InputError(src, where, "MOTION before the hierarchy is complete")
            return nodes, ln
        else:
            raise InputError(src, where, f"unexpected {tok[0]!r}")
    raise InputError(src, "MOTION", "section missing (file truncated?)")


def _floats(tokens: list[str], src: str, where: str, frame: int | None = None) -> np.ndarray:
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        raise InputError(src, where, f"not all numbers: {' '.join(tokens)[:80]}", frame=frame) from None


def _header_value(line: str, key: str, src: str) -> str:
    if not line.lower().startswith(key.lower()):
        raise InputError(src, key.rstrip(":"), f"expected '{key}' line, got {line.strip()[:60]!r}")
    return line.split(":", 1)[1].strip()


def _parse_motion(lines: list[str], start: int, n_channels: int, src: str) -> tuple[np.ndarray, float]:
    """Motion rows ``[T, C]`` (checked: count, width, numbers) and the frame time. Row errors name
    the frame (0-based) and the file line."""
    rest = [(i + 1, ln) for i, ln in enumerate(lines[start + 1 :], start + 1) if ln.strip()]
    if len(rest) < 2:
        raise InputError(src, "Frames", "MOTION header incomplete (file truncated?)")
    frames_s, dt_s = _header_value(rest[0][1], "Frames:", src), _header_value(rest[1][1], "Frame Time:", src)
    if not frames_s.isdigit():
        raise InputError(src, "Frames", f"not a frame count: {frames_s!r}")
    frames = int(frames_s)
    if frames == 0:
        raise InputError(src, "Frames", "has zero frames")
    dt = float(_floats([dt_s], src, "Frame Time")[0])
    if not np.isfinite(dt) or dt <= 0:
        raise InputError(src, "Frame Time", f"must be positive, got {dt_s}")
    rows = rest[2:]
    if len(rows) != frames:
        what = "(truncated?)" if len(rows) < frames else "(extra rows)"
        raise InputError(
            src,
            "MOTION",
            f"file has {len(rows)} motion rows but Frames: says {frames} {what}",
            frame=min(len(rows), frames),
        )
    tokens = [ln.split() for _, ln in rows]
    for k, t in enumerate(tokens):
        if len(t) != n_channels:
            raise InputError(
                src,
                f"MOTION line {rows[k][0]}",
                f"has {len(t)} values, the hierarchy has {n_channels} channels",
                frame=k,
            )
    try:
        motion = np.array(tokens, dtype=np.float64).reshape(frames, n_channels)
    except ValueError:
        k = next(k for k, t in enumerate(tokens) if not _is_numeric(t))
        raise InputError(src, f"MOTION line {rows[k][0]}", "contains a value that is not a number", frame=k) from None
    return motion, dt


def _is_numeric(tokens: list[str]) -> bool:
    try:
        np.array(tokens, dtype=np.float64)
        return True
    except ValueError:
        return False


def parse_bvh(path: str | Path) -> BvhData:
    """Parse a BVH file; every structural or numeric problem is an :class:`InputError`."""
    src = str(path)
    try:
        lines = Path(path).read_text(encoding="utf-8-sig", errors="replace").splitlines()
    except OSError as e:
        raise InputError(src, "file", f"cannot read: {e.strerror}") from None
    first = next((ln.strip() for ln in lines if ln.strip()), "")
    if first.upper() != "HIERARCHY":
        raise InputError(src, "HIERARCHY", "the file does not start with HIERARCHY (not a BVH file?)")
    nodes, motion_line = _parse_hierarchy(lines, src)
    names = [n.name for n in nodes if not n.end_site]
    if len(set(names)) != len(names):
        raise InputError(src, "HIERARCHY", "joint names are not unique")
    n_channels = sum(len(n.channels) for n in nodes)
    motion, dt = _parse_motion(lines, motion_line, n_channels, src)
    bad = ~np.isfinite(motion)
    if bad.any():
        k = int(np.flatnonzero(bad.any(axis=1))[0])
        c = int(np.flatnonzero(bad[k])[0])
        owner = [(n.name, ch) for n in nodes for ch in n.channels][c]
        raise InputError(src, f"{owner[0]}.{owner[1]}", "is NaN or infinite", frame=k)
    _check_rotations(nodes, motion, src)
    return BvhData(nodes, motion, dt)


MAX_ROTATION_DEG = 720.0  # +-4 pi: an Euler angle beyond two full turns is no pose a joint takes, but a broken file
SUSPICIOUS_ROTATION_DEG = 360.0  # beyond a full turn: some exporters unwrap angles so, but rarely that far


def _check_rotations(nodes: list[_Node], motion: np.ndarray, src: str) -> None:
    """An Euler angle beyond +-:data:`MAX_ROTATION_DEG` is an :class:`InputError` naming the joint, channel and
    frame (read on, it wraps to an arbitrary pose without a word); one beyond +-:data:`SUSPICIOUS_ROTATION_DEG` is a
    warning (:func:`pipeline.suspicious.suspect`)."""
    owners = [(n.name, ch) for n in nodes for ch in n.channels]
    rot = np.array([ch.endswith("rotation") for _, ch in owners], dtype=bool)
    for limit in (MAX_ROTATION_DEG, SUSPICIOUS_ROTATION_DEG):
        bad = np.zeros_like(motion, dtype=bool)
        bad[:, rot] = np.abs(motion[:, rot]) > limit
        if not bad.any():
            continue
        k = int(np.flatnonzero(bad.any(axis=1))[0])
        c = int(np.flatnonzero(bad[k])[0])
        name, ch = owners[c]
        if limit == MAX_ROTATION_DEG:
            why = f"{motion[k, c]:.6g} degrees is beyond +-{MAX_ROTATION_DEG:g} (two full turns): not a joint angle"
            raise InputError(src, f"{name}.{ch}", why, frame=k)
        why = f"{motion[k, c]:.6g} degrees is beyond +-{limit:g} (a full turn; {int(bad.sum())} value(s)): read as is"
        suspect(src, f"{name}.{ch}", why, frame=k)


def forward_kinematics(data: BvhData, rest: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Global positions ``[T, N, 3]`` and rotation matrices ``[T, N, 3, 3]`` of all nodes (file axes,
    file units). ``rest=True``: one frame with zero rotations and offsets only."""
    T = 1 if rest else data.motion.shape[0]
    N = len(data.nodes)
    pos, rot = np.zeros((T, N, 3)), np.zeros((T, N, 3, 3))
    col = 0
    for j, node in enumerate(data.nodes):
        vals = data.motion[:, col : col + len(node.channels)]
        col += len(node.channels)
        t = np.repeat(node.offset[None], T, axis=0)
        r = np.broadcast_to(np.eye(3), (T, 3, 3))
        if not rest:
            rot_idx = [k for k, c in enumerate(node.channels) if c.endswith("rotation")]
            for k, c in enumerate(node.channels):
                if c.endswith("position"):
                    t[:, _AXES[c[0]]] = vals[:, k]
            if rot_idx:
                seq = "".join(node.channels[k][0] for k in rot_idx)
                r = Rotation.from_euler(seq, vals[:, rot_idx], degrees=True).as_matrix()
        if node.parent < 0:
            pos[:, j], rot[:, j] = t, r
        else:
            rp = rot[:, node.parent]
            pos[:, j] = pos[:, node.parent] + np.einsum("tab,tb->ta", rp, t)
            rot[:, j] = rp @ r
    return pos, rot


def _leaves(data: BvhData) -> list[int]:
    has_child = {n.parent for n in data.nodes}
    return [i for i in range(len(data.nodes)) if i not in has_child]


def guess_up(data: BvhData, pos: np.ndarray) -> str:
    """``"y"`` or ``"z"``: the axis (of the two) along which the head sits farthest from the feet
    (joints named ``head`` and ``foot``/``toe``/``ankle``), averaged over frames. Without such
    names: the axis of the larger mean leaf-minus-root offset (feet usually dominate)."""
    names = [n.name.lower() for n in data.nodes]
    head = [i for i, n in enumerate(names) if "head" in n and not data.nodes[i].end_site]
    feet = [i for i, n in enumerate(names) if any(k in n for k in ("foot", "toe", "ankle"))]
    if head and feet:
        d = (pos[:, head[0]] - pos[:, feet].mean(axis=1)).mean(axis=0)
    else:
        roots = [i for i, n in enumerate(data.nodes) if n.parent < 0]
        d = (pos[:, _leaves(data)] - pos[:, roots[:1]]).mean(axis=(0, 1))
    return "y" if abs(d[1]) >= abs(d[2]) else "z"


def _rest_height(data: BvhData, A: np.ndarray) -> float | None:
    """Up extent of the rest pose (End Sites included) when it stands upright, else None."""
    pos, _ = forward_kinematics(data, rest=True)
    p = pos[0] @ A.T
    extent = p.max(axis=0) - p.min(axis=0)
    return float(extent[2]) if extent[2] >= 0.75 * max(extent[0], extent[1]) else None


def read_bvh(
    path: str | Path, *, units: str = "auto", up: str = "auto", subject_height: float | None = None
) -> HumanClip:
    """Read a BVH file into a z-up, metre :class:`HumanClip` with global joint orientations.

    ``units``: ``"auto" | "m" | "cm" | "mm" | "inch"``; ``up``: ``"auto" | "y" | "z"``;
    ``subject_height`` (m) overrides the estimate.
    """
    src = str(path)
    if units != "auto":
        unit_scale(units, src)
    if up not in ("auto", "y", "z"):
        raise InputError(src, "up", f"unknown up axis {up!r}; use 'auto', 'y' or 'z'")
    data = parse_bvh(path)
    pos, rot = forward_kinematics(data)
    A = up_matrix(guess_up(data, pos) if up == "auto" else up, src)
    joints = data.joints
    index = {j: k for k, j in enumerate(joints)}
    names = tuple(data.nodes[j].name for j in joints)
    parents = tuple(index[data.nodes[j].parent] if data.nodes[j].parent >= 0 else -1 for j in joints)
    skeleton = Skeleton(names, parents)
    p = pos[:, joints] @ A.T
    raw_height = _rest_height(data, A) or estimate_height(p, skeleton)
    if units == "auto":
        if raw_height is None:
            raise InputError(
                src,
                "units",
                "cannot guess units (no upright rest pose, no head/ankle joints); pass --units m (or cm, mm, inch)",
            )
        units = guess_units(raw_height)
    s = unit_scale(units, src)
    R = np.einsum("ab,tjbc->tjac", A, rot[:, joints])
    quat = wxyz_from_rotation(Rotation.from_matrix(R.reshape(-1, 3, 3))).reshape(R.shape[0], len(joints), 4)
    height = (
        subject_height
        if subject_height is not None
        else plausible_height(None if raw_height is None else raw_height * s)
    )
    return HumanClip(skeleton, p * s, frame_rate(data.frame_time), src, subject_height=height, joint_quat=quat)


def frame_rate(frame_time: float) -> float:
    """``1 / frame_time``, snapped to the nearest integer when within 0.01 (BVH writes rounded
    frame times: 0.008333 s is 120 Hz, 0.033333 s is 30 Hz)."""
    fps = 1.0 / frame_time
    return float(round(fps)) if abs(fps - round(fps)) < 0.01 else fps
