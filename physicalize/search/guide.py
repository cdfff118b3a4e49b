"""What the search changes in the tracked reference (:class:`GuidedReference`): per segment of frames, an offset of
the planned centre of mass, of where a swinging foot is sent and of where the hands are sent, and a scale of the force
the hands plan to apply to a held object, each faded in and out over ``ramp`` frames.

A segment ``[a, b)`` with offsets ``dc`` (CoM, horizontal), ``ds`` (swing foot, horizontal), ``dh`` (both hands, 3-D)
and press ``p`` adds ``w(t) dc`` to the CoM target and ``w'(t) dc`` to its velocity, ``w(t) ds`` to the target of every
foot the schedule has in swing at ``t``, ``w(t) dh`` to both hands' targets, and scales the hands' planned force by
``exp(w(t) p)``; ``w`` rises from 0 to 1 over ``[a, a + ramp)`` by the smoothstep ``3 s^2 - 2 s^3``, holds to ``b``
and falls back to 0 over ``[b, b + ramp)``. Offsets of several segments add. Only the controller's targets move: the
motion is still judged against the retargeted clip, and no force is added to the robot or the object.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from physicalize.reference import Reference
from physicalize.target import Target


@dataclass(frozen=True)
class Segment:
    """Frames ``[start, stop)`` with their CoM offset ``com`` (2,), swing-foot offset ``step`` (2,) and hands' offset
    ``hands`` (3,) [m], and the log-scale ``press`` of the hands' planned force."""

    start: int
    stop: int
    com: tuple[float, float] = (0.0, 0.0)
    step: tuple[float, float] = (0.0, 0.0)
    hands: tuple[float, float, float] = (0.0, 0.0, 0.0)
    press: float = 0.0

    def as_dict(self, fps: float) -> dict:
        """The segment as the figures record it (seconds, metres)."""
        return {
            "start_s": self.start / fps,
            "stop_s": self.stop / fps,
            "com_m": [float(x) for x in self.com],
            "step_m": [float(x) for x in self.step],
            "hands_m": [float(x) for x in self.hands],
            "press": float(self.press),
        }


def fade(frames: int, start: int, stop: int, ramp: int) -> tuple[np.ndarray, np.ndarray]:
    """``(w, dw/dt in 1/frame)`` (``frames``,) of a segment (module docstring)."""
    t = np.arange(frames, dtype=float)
    ramp = max(ramp, 1)

    def smooth(s):
        s = np.clip(s, 0.0, 1.0)
        return 3 * s**2 - 2 * s**3, np.where((s > 0) & (s < 1), 6 * s - 6 * s**2, 0.0) / ramp

    up, dup = smooth((t - start) / ramp)
    down, ddown = smooth((t - stop) / ramp)
    return up - down, dup - ddown


class GuidedReference:
    """``ref`` with the segments' offsets on its targets; every other attribute is the reference's own."""

    def __init__(self, ref: Reference, segments: tuple[Segment, ...], ramp: int):
        self.ref, self.segments = ref, tuple(segments)
        T = ref.frames
        self._com, self._com_vel, self._step = np.zeros((T, 2)), np.zeros((T, 2)), np.zeros((T, 2))
        self._hands, self._press = np.zeros((T, 3)), np.zeros(T)
        for seg in self.segments:
            w, dw = fade(T, seg.start, seg.stop, ramp)
            self._com += w[:, None] * np.asarray(seg.com)
            self._com_vel += dw[:, None] * ref.fps * np.asarray(seg.com)
            self._step += w[:, None] * np.asarray(seg.step)
            self._hands += w[:, None] * np.asarray(seg.hands)
            self._press += w * seg.press

    def __getattr__(self, name: str):
        return getattr(self.ref, name)

    def target(self, t: int) -> Target:
        target = self.ref.target(t)
        k = min(max(t, 0), self.ref.frames - 1)
        if not self.segments:
            return target
        com, com_vel, foot = target.com.copy(), target.com_vel.copy(), target.foot_pos.copy()
        com[:2] += self._com[k]
        com_vel[:2] += self._com_vel[k]
        for f in range(2):
            if not target.stance[f]:
                foot[f, :2] += self._step[k]
        hands = None if target.hand_pos is None else target.hand_pos + self._hands[k]
        force = None if target.hand_force is None else target.hand_force * np.exp(self._press[k])
        return replace(target, com=com, com_vel=com_vel, foot_pos=foot, hand_pos=hands, hand_force=force)
