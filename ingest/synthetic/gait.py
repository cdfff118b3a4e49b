"""Kinematic gait: footstep plans, flat-foot swing trajectories, and the pelvis path over them.

A plan is a list of *stances* (centre between the ankles, heading). Each step moves one foot,
alternating, to its slot in the next stance (``centre +- 0.09 m`` sideways); a closing step
brings the other foot alongside at the end. Feet stay flat: a planted foot does not move at
all; a swinging ankle follows a minimum-jerk path with a ``clearance`` bump (zero vertical
velocity at lift-off and touch-down), raised further where the leg could not reach it (the
knee flexion of early swing). The pelvis is between the feet at mid double support (PCHIP
through those keys: no overshoot, smooth start and stop) plus a lateral sway of 2 cm towards
the stance foot at mid-swing. Its height is the posture's nominal height (3 cm lower while
walking) softly capped by what the planted legs reach (``LEG_REACH``) and smoothed from below:
a ~4 cm bob, lowest in double support.

Walking defaults: step length <= 0.55 m, step period 0.5 s (cadence 2.0 steps/s, stride
frequency 1.0 Hz), swing 0.40 s, double support 0.10 s: about 1.05 m/s at cruise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.ndimage import convolve1d, minimum_filter1d

from ingest.synthetic.skeleton import ANKLE_Z, LEG_REACH, PELVIS_FWD, STANCE_HALF_WIDTH, hip_offsets

SWAY = 0.02


def minjerk(x) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10 - 15 * x + 6 * x**2)


class Keys:
    """A channel set by ``(time, value)`` keys: minimum-jerk between keys, constant outside."""

    def __init__(self, t0: float, value):
        self.keys = [(float(t0), np.asarray(value, dtype=float))]

    def set(self, t: float, value) -> Keys:
        if t <= self.keys[-1][0]:
            raise ValueError(f"key at {t} is not after {self.keys[-1][0]}")
        self.keys.append((float(t), np.asarray(value, dtype=float)))
        return self

    def hold(self, t: float) -> Keys:
        return self.set(t, self.keys[-1][1])

    @property
    def last(self) -> np.ndarray:
        return self.keys[-1][1]

    def __call__(self, t: np.ndarray) -> np.ndarray:
        kt = np.array([k for k, _ in self.keys])
        kv = np.stack([v for _, v in self.keys])
        if len(kt) == 1:
            return np.broadcast_to(kv[0], t.shape + kv.shape[1:]).copy()
        i = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, len(kt) - 2)
        s = minjerk((t - kt[i]) / (kt[i + 1] - kt[i]))
        s = s.reshape(s.shape + (1,) * (kv.ndim - 1))
        return kv[i] + (kv[i + 1] - kv[i]) * s


def _rot2(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def slot(centre, yaw: float, side: int) -> np.ndarray:
    """Ankle xy of foot ``side`` (0 left, 1 right) in the stance (centre, yaw)."""
    return np.asarray(centre, float) + _rot2(yaw) @ np.array(
        [0.0, STANCE_HALF_WIDTH if side == 0 else -STANCE_HALF_WIDTH]
    )


def heading(yaw) -> np.ndarray:
    yaw = np.asarray(yaw, float)
    return np.stack([np.cos(yaw), np.sin(yaw)], axis=-1)


@dataclass
class Step:
    foot: int
    t0: float  # lift-off
    t1: float  # touch-down
    start: np.ndarray
    end: np.ndarray
    yaw0: float
    yaw1: float
    clearance: float


@dataclass
class GaitPlan:
    """Footsteps and pelvis keys, built walk by walk, evaluated at the end."""

    centre: np.ndarray
    yaw: float
    steps: list[Step] = field(default_factory=list)
    keys: list[tuple] = field(default_factory=list)  # (t, pelvis xy without sway, yaw)
    sway: list[tuple] = field(default_factory=list)  # (t, lateral sway xy)
    walks: list[tuple] = field(default_factory=list)  # (start, end) of each walk

    def __post_init__(self):
        self.centre = np.asarray(self.centre, float)
        self.feet = [(slot(self.centre, self.yaw, s), float(self.yaw)) for s in (0, 1)]
        self.feet0 = list(self.feet)
        self._key(0.0, self.centre, self.yaw)
        self.sway.append((0.0, np.zeros(2)))

    def _key(self, t, centre, yaw):
        if self.keys and t <= self.keys[-1][0] + 1e-9:
            raise ValueError(f"gait key at {t:.3f} s is not after the previous one at {self.keys[-1][0]:.3f} s")
        self.keys.append((float(t), np.asarray(centre, float) + PELVIS_FWD * heading(yaw), float(yaw)))

    def walk(
        self, t: float, stances: list[tuple], *, period=0.5, swing=0.4, clearance=0.07, first: int = 0, settle=0.25
    ) -> float:
        """Step through ``stances`` [(centre, yaw), ...], shifting weight from ``t`` and lifting the
        first foot at ``t + 0.15``, then close the feet. Returns when the walker stands still."""
        if t > self.keys[-1][0] + 1e-9:
            self._key(t, self.centre, self.yaw)
            self.sway.append((t, np.zeros(2)))
        prev = (self.centre, self.yaw)
        t_lift = t + 0.15
        seq = list(stances) + [stances[-1]]  # the last entry is the closing step
        for k, (c, y) in enumerate(seq):
            foot = (first + k) % 2
            c, y = np.asarray(c, float), float(y)
            start, yaw0 = self.feet[foot]
            end = slot(c, y, foot)
            self.steps.append(Step(foot, t_lift, t_lift + swing, start, end, yaw0, y, clearance))
            self.feet[foot] = (end, y)
            lateral = self.feet[1 - foot][0] - np.asarray(prev[0], float)  # towards the stance foot
            lateral -= np.dot(lateral, heading(prev[1])) * heading(prev[1])
            self.sway.append((t_lift + swing / 2, SWAY * lateral / np.linalg.norm(lateral)))
            mid_ds = t_lift + swing + (period - swing) / 2
            self.sway.append((mid_ds, np.zeros(2)))
            if k < len(seq) - 1:  # pelvis between the feet in double support
                self._key(mid_ds, 0.5 * (np.asarray(prev[0], float) + c), 0.5 * (prev[1] + y))
            prev = (c, y)
            t_lift += period
        t_end = t_lift - period + swing + settle
        self._key(t_end, prev[0], prev[1])
        self.sway.append((t_end, np.zeros(2)))
        self.centre, self.yaw = prev
        self.walks.append((t, t_end))
        return t_end

    def walking(self, t: np.ndarray, ramp: float = 0.4) -> np.ndarray:
        """(T,) 1 while walking, 0 standing, with minimum-jerk ramps of ``ramp`` seconds."""
        out = np.zeros(len(t))
        for a, b in self.walks:
            out = np.maximum(out, np.minimum(minjerk((t - a) / ramp), minjerk((b - t) / ramp)))
        return out

    def walk_straight(self, t: float, centre, yaw: float | None = None, *, max_step=0.55, **kw) -> float:
        """Walk (forwards, backwards or sideways) to the stance at ``centre``, turning to ``yaw``."""
        centre = np.asarray(centre, float)
        yaw = self.yaw if yaw is None else yaw
        n = max(1, int(np.ceil(np.linalg.norm(centre - self.centre) / max_step - 1e-9)))
        stances = [
            (self.centre + (centre - self.centre) * (k / n), self.yaw + (yaw - self.yaw) * (k / n))
            for k in range(1, n + 1)
        ]
        return self.walk(t, stances, **kw)

    def stance_frames(self, t: np.ndarray) -> np.ndarray:
        """(T,2) True where a foot is planted flat (not strictly inside a swing)."""
        out = np.ones((len(t), 2), bool)
        for s in self.steps:
            out[(t > s.t0) & (t < s.t1), s.foot] = False
        return out

    def feet_at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Planned ankle positions (T,2,3), foot yaws (T,2) and swing progress (T,2): 0 in
        stance, rising from 0 to 1 through each swing."""
        ankles = np.zeros((len(t), 2, 3))
        yaws = np.zeros((len(t), 2))
        progress = np.zeros((len(t), 2))
        ankles[:, :, 2] = ANKLE_Z
        for foot in (0, 1):
            ankles[:, foot, :2], yaws[:, foot] = self.feet0[foot]
        for s in self.steps:
            r = np.clip((t - s.t0) / (s.t1 - s.t0), 0, 1)
            m = t >= s.t0
            g = minjerk(r[m])[:, None]
            ankles[m, s.foot, :2] = s.start + (s.end - s.start) * g
            yaws[m, s.foot] = s.yaw0 + (s.yaw1 - s.yaw0) * g[:, 0]
            ankles[m, s.foot, 2] = ANKLE_Z + s.clearance * (4 * r[m] * (1 - r[m])) ** 2
            progress[(t > s.t0) & (t < s.t1), s.foot] = r[(t > s.t0) & (t < s.t1)]
        return ankles, yaws, progress

    def pelvis_xy(self, t: np.ndarray, sway: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Pelvis xy (T,2), with or without the lateral sway, and heading (T,), by PCHIP."""
        kt = np.array([k[0] for k in self.keys])
        tt = np.clip(t, kt[0], kt[-1])
        xy = PchipInterpolator(kt, np.stack([k[1] for k in self.keys]), axis=0)(tt)
        yaw = PchipInterpolator(kt, np.array([k[2] for k in self.keys]))(tt)
        if sway:
            st = np.array([k[0] for k in self.sway])
            xy = xy + PchipInterpolator(st, np.stack([k[1] for k in self.sway]), axis=0)(np.clip(t, st[0], st[-1]))
        return xy, yaw


def pelvis_height(nominal, pelvis_xy, yaw, pelvis_pitch, ankles, progress, k=0.008) -> np.ndarray:
    """``nominal`` pelvis height softly capped (always below) by the legs' reach to the planted
    ankles. A swinging foot's cap is relaxed (by up to 0.3 m mid-swing): its knee bends instead
    (see :func:`lift_swing_feet`)."""
    hips = hip_offsets(yaw, pelvis_pitch)  # (T,2,3)
    horiz = np.linalg.norm(pelvis_xy[:, None] + hips[..., :2] - ankles[..., :2], axis=-1)
    if np.any((horiz > 0.9 * LEG_REACH) & (progress == 0)):
        raise ValueError("a planted foot is out of the legs' horizontal reach")
    caps = ankles[..., 2] - hips[..., 2] + np.sqrt(LEG_REACH**2 - horiz**2) + 0.3 * np.sin(np.pi * progress) ** 2
    z = np.concatenate([np.asarray(nominal, float)[:, None], caps], axis=1)
    m = z.min(axis=1)
    return m - k * np.log(np.exp(-(z - m[:, None]) / k).sum(axis=1))


def smooth_below(z: np.ndarray, half_window: int) -> np.ndarray:
    """A smoothed copy of ``z`` that is nowhere above it: a minimum filter, then a Hann-weighted
    average over the same window (each averaged minimum is <= z at the window's centre)."""
    if half_window < 1:
        return z
    w = np.hanning(2 * half_window + 3)[1:-1]
    m = minimum_filter1d(z, 2 * half_window + 1, mode="nearest")
    return np.minimum(convolve1d(m, w / w.sum(), mode="nearest"), z)


def lift_swing_feet(pelvis, yaw, pelvis_pitch, ankles, progress, k=0.005) -> np.ndarray:
    """Ankle targets with swinging feet raised (softly) where the leg could not reach them."""
    hips = pelvis[:, None] + hip_offsets(yaw, pelvis_pitch)
    horiz = np.linalg.norm(hips[..., :2] - ankles[..., :2], axis=-1)
    lowest = hips[..., 2] - np.sqrt(np.maximum(LEG_REACH**2 - horiz**2, 0.0))
    lift = k * np.logaddexp(0.0, (lowest - ankles[..., 2]) / k)
    out = ankles.copy()
    out[..., 2] += np.where(progress > 0, lift, 0.0)
    return out
