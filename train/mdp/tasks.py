"""Task success, as the paper's appendix ("Evaluation Metrics") defines it, measured step by step on the
simulated state (:class:`TaskMeter`, one per environment):

* **PickUp** -- the box lifted more than :attr:`Rules.lift_m` above the ground (its lowest point) and held
  there for :attr:`Rules.hold_s` without a break;
* **SitStand** -- stable pelvis-chair contact (the pelvis or hip geoms touching the chair for
  :attr:`Rules.sit_s`) with the root height within :attr:`Rules.seat_height_m`;
* **Carry** -- the box picked up (lowest point above :attr:`Rules.pick_m`), never farther than
  :attr:`Rules.carry_tolerance_m` from its reference track, and placed: at the episode's last step resting on the
  floor (lowest point below :attr:`Rules.rest_m`) within that tolerance of the track's end
  (:attr:`TaskMeter.track_end`; measured: comparing with the track at the last step instead credited a policy that
  fell with the box, 25% of episodes);
* **Push** -- the hand-object contact rate, over the frames the reference pushes (its hands on the object) in
  the whole episode (:attr:`TaskMeter.push_total`): the share with a hand touching it, so the pushing frames after
  a fall count as without contact (measured: counting only the frames before the fall gave a policy that fell in
  every episode 82% at scale 1.0); body-dominated contact (more frames of other links on the object than of
  hands) counts as failure (rate 0). Its ``success`` is ``rate >= Rules.push_success_rate``.

A fall (:func:`pipeline.terms.fall.fallen`) ends the episode; what was achieved before it stands.

**Root tracking accuracy** ``R_acc`` (App. "Evaluation Metrics", Table 3's real-world deployment): the share of the
episode's control steps whose root is within :attr:`Rules.root_tolerance_m` (0.6 m) of the commanded root trajectory,

    R_acc = #{t : d_t <= 0.6 m} / T,    d_t = |p_root(t) - p_cmd(t)|_xy,

for every task (:attr:`TaskMeter.root_accuracy`). ``d_t`` is :attr:`StepFacts.root_dev_m`, filled by the environment
(:meth:`train.envs.cpu.env.EnvSlot.facts` says what the commanded trajectory is and why the distance is horizontal).
``T`` is the episode's full length in control steps (:attr:`TaskMeter.root_total`), not the steps run: the steps a
fall cut off count as off the track, so a policy that falls at step 10 of 500 scores at most 2%, not 100% (the same
reason as Push's denominator above).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from train.episodes import TASKS


@dataclass(frozen=True)
class Rules:
    lift_m: float = 0.3
    hold_s: float = 3.0
    seat_height_m: tuple[float, float] = (0.3, 0.6)
    sit_s: float = 1.0
    pick_m: float = 0.1
    rest_m: float = 0.05
    carry_tolerance_m: float = 0.6
    push_success_rate: float = 0.5
    root_tolerance_m: float = 0.6  # R_acc: the root's horizontal distance to the commanded trajectory


@dataclass
class StepFacts:
    """What one control step measured in one environment (filled by the environment)."""

    object_low: float  # the object's lowest point above the floor [m]
    object_pos: np.ndarray  # (3,) its position
    object_ref: np.ndarray  # (3,) its reference track's position at this step
    root_z: float
    root_dev_m: float  # the root's horizontal distance to the commanded root trajectory at this step (R_acc)
    pelvis_on_object: bool  # pelvis / hip geoms touching the object
    hand_on_object: bool
    body_on_object: bool  # another robot link (not hands, not feet) touching it
    reference_pushing: bool  # the reference's hands touch the object at this step


@dataclass
class TaskMeter:
    """Accumulates one episode's success figures (module docstring)."""

    task: str
    fps: float
    rules: Rules = field(default_factory=Rules)
    steps: int = 0
    run: int = 0  # consecutive steps meeting PickUp's / SitStand's condition
    best_run: int = 0
    picked: bool = False
    max_dev: float = 0.0
    last: StepFacts | None = None
    track_end: np.ndarray | None = None  # Carry: the object's reference position at the track's end
    push_total: int = 0  # the frames the reference pushes in the whole episode (the rate's denominator)
    push_frames: int = 0  # of them, the frames stepped so far
    hand_frames: int = 0
    body_frames: int = 0
    seat_run: int = 0  # consecutive steps of pelvis-chair contact at any root height (SitStand's diagnosis)
    best_seat_run: int = 0
    seat_root_z: list[float] = field(default_factory=list)  # root heights while the pelvis touches the chair
    root_total: int = 0  # the episode's full length in control steps (R_acc's denominator)
    root_within: int = 0  # of the steps run, those with the root within Rules.root_tolerance_m of the command

    def __post_init__(self):
        if self.task not in TASKS:
            raise ValueError(f"unknown task {self.task!r}; known: {TASKS}")
        if self.task == "Carry" and self.track_end is None:
            raise ValueError("a Carry meter needs the track's end (track_end)")

    def update(self, f: StepFacts) -> None:
        r = self.rules
        self.steps += 1
        self.last = f
        if self.task == "PickUp":
            held = f.object_low > r.lift_m
        elif self.task == "SitStand":
            held = f.pelvis_on_object and r.seat_height_m[0] <= f.root_z <= r.seat_height_m[1]
        else:
            held = False
        self.run = self.run + 1 if held else 0
        self.best_run = max(self.best_run, self.run)
        if self.task == "SitStand":
            self.seat_run = self.seat_run + 1 if f.pelvis_on_object else 0
            self.best_seat_run = max(self.best_seat_run, self.seat_run)
            if f.pelvis_on_object:
                self.seat_root_z.append(f.root_z)
        self.picked |= f.object_low > r.pick_m
        self.root_within += f.root_dev_m <= r.root_tolerance_m
        self.max_dev = max(self.max_dev, float(np.linalg.norm(f.object_pos - f.object_ref)))
        if f.reference_pushing:
            self.push_frames += 1
            self.hand_frames += f.hand_on_object
            self.body_frames += f.body_on_object

    @property
    def contact_rate(self) -> float:
        """Push's hand-object contact rate (0 when body contact dominates or nothing was pushed)."""
        if not self.push_frames or self.body_frames > self.hand_frames:
            return 0.0
        return self.hand_frames / max(self.push_total, self.push_frames)

    @property
    def root_accuracy(self) -> float:
        """``R_acc`` (module docstring): the steps on the track over the episode's full length (the steps run when
        longer, e.g. a meter fed by hand without ``root_total``); 0 before any step."""
        total = max(self.root_total, self.steps)
        return self.root_within / total if total else 0.0

    @property
    def success(self) -> bool:
        r = self.rules
        if self.task == "PickUp":
            return self.best_run >= r.hold_s * self.fps
        if self.task == "SitStand":
            return self.best_run >= r.sit_s * self.fps
        if self.task == "Push":
            return self.contact_rate >= r.push_success_rate
        f = self.last
        placed = (
            f is not None
            and f.object_low < r.rest_m
            and float(np.linalg.norm(f.object_pos - self.track_end)) <= r.carry_tolerance_m
        )
        return self.picked and self.max_dev <= r.carry_tolerance_m and placed

    def summary(self) -> dict:
        """The episode's figures (``root_accuracy``: ``R_acc``, 0..1); SitStand adds why a sit failed: the longest
        pelvis-chair contact at any root height (``seated_s``) and the median root height during contact
        (``seated_root_z_m``, None if none)."""
        out = {
            "task": self.task,
            "steps": self.steps,
            "success": bool(self.success),
            "contact_rate": self.contact_rate,
            "max_object_dev_m": self.max_dev,
            "root_accuracy": self.root_accuracy,
        }
        if self.task == "SitStand":
            out["seated_s"] = self.best_seat_run / self.fps
            out["seated_root_z_m"] = float(np.median(self.seat_root_z)) if self.seat_root_z else None
        return out
