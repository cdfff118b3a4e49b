"""Depth noise as real sensors have it: an Intel RealSense D435-like corruption of the clean z-depth image of
:class:`train.vision.camera.DepthCamera`, and :class:`DepthSensor`, one environment's sensor through an episode.

**The terms** (each a plain function below, its range a field of :class:`DepthNoise`), applied in this order to a
clean (H, W) image ``z`` in metres:

1. *Stereo noise* (:func:`stereo_noise`): an active-stereo camera measures disparity ``d = f b / z`` (focal ``f``
   in pixels, baseline ``b``) with a sub-pixel RMS error ``s``; to first order the depth error is
   ``sigma_z = z^2 s / (f b) = c z^2`` (Intel, "Tuning depth cameras for best performance", RMS-error formula).
   The D435 (``b`` = 50 mm, 848 px over 87 degrees: ``f`` = 447 px) with ``s`` ~ 0.08 px gives ``c`` ~ 0.0036 m^-1:
   3.6 mm at 1 m, 14 mm at 2 m, within the datasheet's "< 2 % at 2 m". The range drawn per episode starts at 0:
   a 64-wide image binned from the native 848 would average some of it away (assumed, not measured).
2. *Quantisation* (:func:`quantise_disparity`): disparity comes in steps ``delta``, so depth sits on the grid
   ``z_n = 1 / (q n)`` (n a whole number) whose spacing grows as ``q z^2`` with ``q = delta / (f b)``, the depth
   step at 1 m. Taken: ``delta`` = 1/32 px (assumed for the D4's sub-pixel resolution), ``q`` = 1.4 mm.
3. Values are clipped back into ``[near, far]``; then pixels are made *invalid*, reading **0.0**, which is what a
   RealSense reports for "no depth" (``depth_to_mm`` stores it as 0 too): per-pixel *dropout*
   (:func:`dropout_mask`), rectangular *holes* (:func:`hole_mask`: specular or texture-less patches the matcher
   cannot fill), and *edges* (:func:`edge_mask`: beside a depth jump from ``z_1`` to ``z_2`` the background seen
   by one imager only, a band ``f b |1/z_1 - 1/z_2|`` pixels wide, fails the left-right check: 11 of the 848 native
   pixels for 1 m against 2 m, ~0.85 of a 64-wide image's 13-native-pixel pixels, on one side of the jump; the
   mask takes both sides, each with ``edge_prob`` = 0.5). Every valid pixel stays in ``[near, far]``.

**The sensor** (:class:`DepthSensor`) adds what is not in one image: per-episode extrinsics (the mount is never
where the URDF says) plus per-step jitter (mount flex, vibration) as a
:class:`~train.vision.camera.CameraOffset`, a latency of whole control steps (exposure, the ASIC's pipeline, USB
and the driver; assumed: one to two frames at 60-90 fps plus transfer, 0..2 steps of 20 ms), and repeated frames
(the same frame delivered twice: a dropped USB frame, or a stream slower than control).

:meth:`DepthNoise.off` disables everything: the sensor then reads exactly ``camera.render(m, d)``. Per-frame cost
matters (a 64 x 40 image every 20 ms in each of several environments): every term is a few vectorised numpy
operations, skipped when disabled.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, fields

import mujoco
import numpy as np

from pipeline.errors import InputError
from train.vision.camera import CameraOffset, DepthCamera

FILE = "depth noise"
MM = 1000.0  # storage: uint16 millimetres


@dataclass(frozen=True)
class DepthNoise:
    """How a :class:`DepthSensor` corrupts depth (module docstring); the defaults are the training randomisation.

    ``(low, high)`` fields are ranges: per episode (drawn by :meth:`draw`) for ``stereo_coeff``, ``dropout`` and
    ``latency``, per frame for ``holes``. Integer ranges include both ends. Checked on construction."""

    stereo_coeff: tuple[float, float] = (0.0, 0.004)  # m^-1: sigma_z = c z^2; D435 ~0.0036, 0 for a clean episode
    quant_step_1m: float = 0.0014  # m: disparity step (1/32 px) at 1 m; the step is quant_step_1m z^2; 0 = off
    dropout: tuple[float, float] = (0.0, 0.02)  # per-pixel invalid probability; D435 fill rate spec > 99 %
    holes: tuple[int, int] = (0, 2)  # rectangular invalid blobs per frame (assumed)
    hole_size: tuple[int, int] = (2, 8)  # px, each side of a hole, at 64 x 40 (assumed)
    edge_threshold: float = 0.2  # m: a 4-neighbour jump above this marks an edge (object vs background)
    edge_prob: float = 0.5  # an edge pixel is invalid with this probability: module docstring, "edges"
    repeat_prob: float = 0.05  # the sensor returns its previous frame again (assumed: USB drops)
    latency: tuple[int, int] = (0, 2)  # control steps (20 ms), per episode: one to two frames at 60-90 fps (assumed)
    extrinsic_pos: float = 0.01  # m: per-episode offset, uniform in +-this on each body axis (mount tolerance)
    extrinsic_rot: float = 0.02  # rad: per-episode roll, pitch, yaw uniform in +-this (~1.1 degrees)
    jitter_pos: float = 0.001  # m: per-step normal std on each axis (mount flex, vibration; assumed)
    jitter_rot: float = 0.002  # rad: per-step normal std of roll, pitch, yaw (assumed)

    @classmethod
    def off(cls) -> DepthNoise:
        """No noise at all: a :class:`DepthSensor` then reads exactly ``camera.render``."""
        return cls(
            stereo_coeff=(0.0, 0.0),
            quant_step_1m=0.0,
            dropout=(0.0, 0.0),
            holes=(0, 0),
            edge_prob=0.0,
            repeat_prob=0.0,
            latency=(0, 0),
            extrinsic_pos=0.0,
            extrinsic_rot=0.0,
            jitter_pos=0.0,
            jitter_rot=0.0,
        )

    def __post_init__(self):
        ranges = {"stereo_coeff": float, "dropout": float, "holes": int, "hole_size": int, "latency": int}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ranges:
                _check_range(f.name, value, ranges[f.name])
                object.__setattr__(self, f.name, tuple(value))
            elif isinstance(value, bool) or not isinstance(value, int | float | np.number) or not 0 <= value < np.inf:
                raise InputError(FILE, f.name, f"{value!r} is not a finite number >= 0")
        for name in ("dropout", "edge_prob", "repeat_prob"):
            if np.max(getattr(self, name)) > 1.0:
                raise InputError(FILE, name, f"{getattr(self, name)!r}: a probability is in [0, 1]")
        if self.hole_size[0] < 1:
            raise InputError(FILE, "hole_size", f"{self.hole_size!r}: a hole is at least 1 pixel a side")
        if self.edge_threshold <= 0.0:
            raise InputError(FILE, "edge_threshold", f"{self.edge_threshold!r} must be > 0 m")

    def draw(self, rng: np.random.Generator) -> EpisodeDraw:
        """One episode's values: the extrinsic offset, latency, stereo coefficient and dropout probability."""
        a, r = self.extrinsic_pos, self.extrinsic_rot
        offset = CameraOffset(
            tuple(rng.uniform(-a, a, 3)) if a > 0 else (0.0, 0.0, 0.0),
            tuple(rng.uniform(-r, r, 3)) if r > 0 else (0.0, 0.0, 0.0),
        )
        return EpisodeDraw(
            offset=offset,
            latency=int(rng.integers(self.latency[0], self.latency[1] + 1)),
            stereo_coeff=_uniform(rng, self.stereo_coeff),
            dropout=_uniform(rng, self.dropout),
        )

    def jitter(self, rng: np.random.Generator) -> CameraOffset | None:
        """One step's jitter: normal with std ``jitter_pos`` (m) and ``jitter_rot`` (rad) on each axis; ``None``
        when both are 0."""
        if self.jitter_pos == 0 and self.jitter_rot == 0:
            return None
        pos = tuple(rng.normal(0.0, self.jitter_pos, 3)) if self.jitter_pos > 0 else (0.0, 0.0, 0.0)
        rot = tuple(rng.normal(0.0, self.jitter_rot, 3)) if self.jitter_rot > 0 else (0.0, 0.0, 0.0)
        return CameraOffset(pos, rot)


@dataclass(frozen=True)
class EpisodeDraw:
    """The values :meth:`DepthNoise.draw` fixes for one episode."""

    offset: CameraOffset
    latency: int  # control steps
    stereo_coeff: float  # m^-1
    dropout: float  # per-pixel probability


def _check_range(name: str, value, kind: type) -> None:
    if not isinstance(value, tuple | list) or len(value) != 2:
        raise InputError(FILE, name, f"{value!r} is not a (low, high) pair")
    for v in value:
        ok = (
            isinstance(v, int | np.integer)
            if kind is int
            else isinstance(v, int | float | np.number) and np.isfinite(v)
        )
        if isinstance(v, bool) or not ok or v < 0:
            raise InputError(FILE, name, f"{value!r}: {'an integer' if kind is int else 'a finite number'} >= 0 each")
    if value[0] > value[1]:
        raise InputError(FILE, name, f"{value!r}: low must be <= high")


def _uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(rng.uniform(*bounds)) if bounds[1] > bounds[0] else float(bounds[0])


def stereo_noise(z: np.ndarray, coeff: float, rng: np.random.Generator) -> np.ndarray:
    """``z + N(0, (coeff z^2)^2)`` per pixel: stereo depth's RMS error ``sigma_z = z^2 s / (f b)`` (module
    docstring), float32. ``coeff`` = 0 returns ``z`` itself."""
    if coeff <= 0.0:
        return z
    e = rng.standard_normal(z.shape, dtype=np.float32)
    e *= np.float32(coeff)
    e *= z
    e *= z
    e += z
    return e


def quantise_disparity(z: np.ndarray, step_1m: float) -> np.ndarray:
    """``z`` snapped to the nearest disparity level: ``1 / (q round(1 / (q z)))`` with ``q = step_1m`` (m), a grid
    whose spacing is ``q z^2`` (1.4 mm at 1 m, 5.6 mm at 2 m for the default). ``step_1m`` = 0 returns ``z`` itself;
    depths at or below 0 are left as they are."""
    if step_1m <= 0.0:
        return z
    n = np.rint(1.0 / (step_1m * np.maximum(z, 1e-6, dtype=np.float64)))
    return np.where(z > 0, 1.0 / (step_1m * np.maximum(n, 1.0)), z).astype(np.float32)


def dropout_mask(shape: tuple[int, int], p: float, rng: np.random.Generator) -> np.ndarray | None:
    """Each pixel invalid independently with probability ``p`` (bool mask); ``None`` when ``p`` = 0."""
    return rng.random(shape, dtype=np.float32) < p if p > 0.0 else None


def hole_mask(shape: tuple[int, int], count: int, size: tuple[int, int], rng: np.random.Generator) -> np.ndarray | None:
    """``count`` axis-aligned rectangles, each side uniform in ``size`` pixels (ends included), centred on a uniform
    pixel (cut by the image border); ``None`` when ``count`` = 0."""
    if count <= 0:
        return None
    h, w = shape
    u = rng.random((4, count))  # one draw for every hole: its centre row, column, height and width
    span = size[1] - size[0] + 1
    heights, widths = (size[0] + (u[2:] * span).astype(int)).clip(max=size[1])
    tops = (u[0] * h).astype(int) - heights // 2
    lefts = (u[1] * w).astype(int) - widths // 2
    mask = np.zeros(shape, dtype=bool)
    for top, left, hh, ww in zip(tops, lefts, heights, widths):  # a few holes: a slice each
        mask[max(top, 0) : max(top + hh, 0), max(left, 0) : max(left + ww, 0)] = True
    return mask


def depth_edges(z: np.ndarray, threshold: float) -> np.ndarray:
    """Pixels with a 4-neighbour whose depth differs by more than ``threshold`` m (both sides of the jump)."""
    edges = np.zeros(z.shape, dtype=bool)
    rows = np.abs(np.diff(z, axis=0)) > threshold
    cols = np.abs(np.diff(z, axis=1)) > threshold
    edges[:-1] |= rows
    edges[1:] |= rows
    edges[:, :-1] |= cols
    edges[:, 1:] |= cols
    return edges


def edge_mask(z: np.ndarray, threshold: float, p: float, rng: np.random.Generator) -> np.ndarray | None:
    """Each :func:`depth_edges` pixel of ``z`` invalid with probability ``p``; ``None`` when ``p`` = 0."""
    if p <= 0.0:
        return None
    edges = depth_edges(z, threshold)
    edges[edges] = rng.random(np.count_nonzero(edges), dtype=np.float32) < p  # a draw per edge pixel only
    return edges


def corrupt(
    clean: np.ndarray,
    noise: DepthNoise,
    episode: EpisodeDraw,
    near: float,
    far: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """The image terms in order (module docstring): stereo noise, quantisation, clipping to ``[near, far]``, then
    dropout, holes and edges (found on ``clean``) read 0.0. Everything off returns ``clean`` itself."""
    z = quantise_disparity(stereo_noise(clean, episode.stereo_coeff, rng), noise.quant_step_1m)
    if z is not clean:
        z = np.clip(z, near, far)
    count = int(rng.integers(noise.holes[0], noise.holes[1] + 1)) if noise.holes[1] > 0 else 0
    masks = (
        dropout_mask(clean.shape, episode.dropout, rng),
        hole_mask(clean.shape, count, noise.hole_size, rng),
        edge_mask(clean, noise.edge_threshold, noise.edge_prob, rng),
    )
    masks = [k for k in masks if k is not None]
    if masks:
        z = np.where(np.logical_or.reduce(masks), np.float32(0.0), z)
    return z


class DepthSensor:
    """One environment's depth sensor: ``camera`` corrupted by ``noise``, randomised by ``rng`` (module docstring).

    :meth:`reset` at each episode start (the constructor does the first); :meth:`read` once per control step.
    Returned frames are read-only (they are also the latency buffer's)."""

    def __init__(self, camera: DepthCamera, noise: DepthNoise, rng: np.random.Generator):
        self.camera, self.noise, self.rng = camera, noise, rng
        self.reset()

    def reset(self) -> None:
        """Draw the episode's values (:attr:`episode`) and empty the latency buffer."""
        self.episode = self.noise.draw(self.rng)
        self._frames: deque[np.ndarray] = deque(maxlen=self.episode.latency + 1)
        self._last: np.ndarray | None = None

    def read(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        """(H, W) float32 depth: this step's frame, seen from the episode's extrinsics plus this step's jitter and
        corrupted, enters the latency buffer; the frame ``latency`` steps old comes out (the episode's first frame
        until there is one that old). With probability ``repeat_prob`` the previous output comes out again."""
        jitter = self.noise.jitter(self.rng)
        offset = self.episode.offset if jitter is None else self.episode.offset + jitter
        clean = self.camera.render(m, d, offset)
        frame = corrupt(clean, self.noise, self.episode, self.camera.near, self.camera.far, self.rng)
        frame.setflags(write=False)
        if self._frames:
            self._frames.append(frame)
        else:
            self._frames.extend([frame] * self._frames.maxlen)
        if self._last is not None and self.noise.repeat_prob > 0 and self.rng.random() < self.noise.repeat_prob:
            return self._last
        self._last = self._frames[0]
        return self._last


def depth_to_mm(z: np.ndarray) -> np.ndarray:
    """Depth in metres as uint16 millimetres (the RealSense's own storage, depth unit 1 mm): rounded to the nearest
    millimetre, 0 (invalid) stays 0, non-finite reads 0, beyond 65.535 m saturates."""
    mm = np.rint(np.nan_to_num(np.asarray(z, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0) * MM)
    return np.clip(mm, 0, np.iinfo(np.uint16).max).astype(np.uint16)


def mm_to_depth(mm: np.ndarray) -> np.ndarray:
    """uint16 millimetres back to float32 metres (0 stays 0: invalid)."""
    return (np.asarray(mm, dtype=np.float64) / MM).astype(np.float32)
