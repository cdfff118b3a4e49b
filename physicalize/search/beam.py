"""Beam search over the guided reference's segments (:mod:`physicalize.search.guide`), with the QP teacher in the
loop, where the teacher's rollout falls.

From :attr:`SearchConfig.start_before_s` before the nominal rollout's drift onset (its pelvis 5 cm off the
reference, :mod:`physicalize.balance`), segment by segment of :attr:`SearchConfig.segment_s`:

* every elite of the beam (a snapshot of the tracker at the segment's start and the segments chosen so far,
  :class:`physicalize.rollout.Tracker`) has :attr:`SearchConfig.children` children: the first with no offset, the
  others with offsets drawn from ``N(0, sigma)`` (CoM and swing foot, per axis) by a generator seeded with
  :attr:`SearchConfig.seed`;
* each child is simulated over its segment (snapshot at its end) and a lookahead of
  :attr:`SearchConfig.lookahead_s`, and scored by :func:`cost`;
* the :attr:`SearchConfig.beam` cheapest children are the next elites.

A step's children run in this process or over worker processes (:mod:`physicalize.search.children`: the offsets are
drawn here, in one order, so the result is the same for any number of workers).

Then the best elite's segments are re-simulated from frame 0 in a fresh tracker (the same arithmetic, so the same
rollout), to be validated as every rollout is. Where the best elite stands clean over its segment and lookahead, its
continuation is simulated to the end and the search resumes only where that continuation drifts (:func:`_skip_ahead`).
The search stops early when the control frames it simulated reach its budget (:func:`frame_budget`, from
:attr:`SearchConfig.children_per_s`, shared by the attempts: a count, not a clock, so that a seed gives the same result
on any machine, and a count of frames, not of children, as the CPU time is): the segments chosen so far are kept.
Why: with no object at all, 12 of the 20 shared real takes fell while walking (``bench_physicalize_real.py
--robot-only``), each after its capture-point step saturated; an offline plan alone cannot know the states the
robot reaches, and an open-loop sampler without the QP's balance in the loop did not repair a fall (FIELD-NOTES).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from physicalize.balance import DRIFT_M
from physicalize.object_trace import OBJECT_DRIFT_M
from physicalize.reference import Reference
from physicalize.rollout import Rollout, Snapshot, Tracker
from physicalize.search.children import Children
from physicalize.search.guide import GuidedReference, Segment
from physicalize.validate import LIMIT_TOL, OBJECT_LOST_M, Bars
from physicalize.wbc import WholeBodyController
from pipeline.robot import G1_JOINT_NAMES, JOINTS_QPOS
from pipeline.scene import Scene

FALL_COST = 100.0
BAR_COST = 1.0
BARS = Bars()


@dataclass(frozen=True)
class SearchConfig:
    """The search's budget and spread (seconds of the reference, metres)."""

    segment_s: float = 0.5
    lookahead_s: float = 0.5
    children: int = 12
    beam: int = 3
    com_sigma_m: float = 0.03
    step_sigma_m: float = 0.05
    # drawn only for a clip with objects (after the CoM and step draws: a robot-alone search is unchanged by them)
    hands_sigma_m: float = 0.03
    press_sigma: float = 0.3  # of the log-scale of the hands' planned force
    ramp_s: float = 0.1
    start_before_s: float = 1.0
    # the budget, as the control frames of this many children (segment_s + lookahead_s each) per second of the
    # reference, all attempts together (frame_budget): 1.6-2.6 ms of CPU a frame (the robot alone - with an object
    # in the QP). The 20 shared takes (BENCHMARKS.md): the robot alone 18 valid at 100, 120, 150 and 220, at most
    # 11-13 CPU-s per second of motion; with the objects at most 16.8 at 100, 20.3 at 120, 22.7 at 150
    children_per_s: float = 100.0
    seed: int = 0
    attempts: int = 3  # searches with seeds seed, seed + 1, ... until one is valid, sharing the budget

    def __post_init__(self):
        for name in ("segment_s", "lookahead_s", "ramp_s", "children_per_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"SearchConfig.{name}: must be > 0, got {getattr(self, name)}")
        for name in ("children", "beam", "attempts"):
            if getattr(self, name) < 1:
                raise ValueError(f"SearchConfig.{name}: must be >= 1, got {getattr(self, name)}")
        for name in ("com_sigma_m", "step_sigma_m", "hands_sigma_m", "press_sigma", "start_before_s"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"SearchConfig.{name}: must be >= 0, got {getattr(self, name)}")


@dataclass(frozen=True)
class Elite:
    snapshot: Snapshot
    segments: tuple[Segment, ...]
    cost: float


@dataclass
class SearchResult:
    """The re-simulated rollout of the best segments, and what the search cost."""

    rollout: Rollout
    segments: tuple[Segment, ...]
    cpu_s: float  # of every process the search ran in
    worker_cpu_s: float  # of those its children ran in (physicalize.search.children; 0 with none)
    children: int
    frames: int  # control frames simulated by the search (its children, continuations and skips; not the re-run)
    start: int


def frame_budget(config: SearchConfig, frames: int, fps: float) -> int:
    """The search's budget of simulated control frames for a reference of ``frames``: as many as
    :attr:`SearchConfig.children_per_s` children of a segment plus a lookahead each would simulate."""
    per_child = max(int(round(config.segment_s * fps)), 1) + int(round(config.lookahead_s * fps))
    return int(config.children_per_s * frames / fps) * per_child


def drift_onset(
    ref: Reference,
    qpos: np.ndarray,
    fell_at: int | None,
    objects: tuple[tuple[int, np.ndarray], ...] = (),
    since: int = 0,
) -> int:
    """First frame from ``since`` on whose pelvis is :data:`physicalize.balance.DRIFT_M` off ``ref``'s or an object
    :data:`OBJECT_DRIFT_M` off its reference track (``objects``: (qpos address, track) pairs); else the fall ``fell_at``
    (else the end). ``qpos``: the rollout's frames ``since, since + 1, ...`` (what a restored tracker recorded)."""
    stop = since + len(qpos)
    err = np.linalg.norm(qpos[:, :2] - ref.qpos[since:stop, :2], axis=1) > DRIFT_M
    for adr, track in objects:
        err |= np.linalg.norm(qpos[:, adr : adr + 3] - track[since:stop, :3], axis=1) > OBJECT_DRIFT_M
    far = np.flatnonzero(err)
    return since + int(far[0]) if far.size else (fell_at or stop)


@dataclass(frozen=True)
class Scorer:
    """What a child's cost reads: the reference, the G1 joints' ranges widened by the validity tolerance
    (:data:`physicalize.validate.LIMIT_TOL`) and the objects' reference tracks at their ``qpos`` addresses."""

    ref: Reference
    lo: np.ndarray
    hi: np.ndarray
    objects: tuple[tuple[int, np.ndarray], ...] = ()

    @classmethod
    def of(cls, scene: Scene, ref: Reference, objects: dict[str, np.ndarray] | None = None) -> Scorer:
        m = scene.model
        lo, hi = m.jnt_range[[m.joint(j).id for j in G1_JOINT_NAMES]].T
        tracks = tuple((scene.object_qpos_adr[n], np.asarray(p)) for n, p in (objects or {}).items())
        return cls(ref, lo - LIMIT_TOL, hi + LIMIT_TOL, tracks)

    def cost(self, tracker: Tracker, start: int, stop: int, segment: Segment) -> float:
        """A child's cost over frames ``[start, stop)``, the validity bars first: :data:`FALL_COST` times the share of
        the window lost to a fall; :data:`BAR_COST` times the number of its frames with a joint past its range, a
        contact deeper than the penetration bar, the pelvis farther than the root bar from the reference or an object
        lost (:class:`physicalize.validate.Bars`, :data:`physicalize.validate.OBJECT_LOST_M`); then the pelvis's and
        the objects' mean distance from their reference and the pelvis's final one, and a tenth of the offsets' size
        (of two equal rollouts, the one that changes less)."""
        qpos = np.asarray(tracker.rec["qpos"][start:stop])
        if not len(qpos):
            return FALL_COST
        ref = self.ref.qpos[start : start + len(qpos)]
        err = np.linalg.norm(qpos[:, :2] - ref[:, :2], axis=1)
        missed = np.linalg.norm(qpos[:, :3] - ref[:, :3], axis=1) > BARS.root_pos_err_max_m
        joints = qpos[:, JOINTS_QPOS]
        missed |= ((joints < self.lo) | (joints > self.hi)).any(axis=1)
        missed |= np.asarray(tracker.rec["penetration"][start:stop]) > BARS.penetration_max_m
        soft = float(err.mean() + err[-1])
        for adr, track in self.objects:
            e = np.linalg.norm(qpos[:, adr : adr + 3] - track[start : start + len(qpos), :3], axis=1)
            missed |= e > OBJECT_LOST_M
            soft += float(e.mean())
        lost = 0.0 if tracker.fell_at is None else 1.0 - (tracker.fell_at - start) / max(stop - start, 1)
        size = float(
            np.linalg.norm(segment.com) + np.linalg.norm(segment.step) + np.linalg.norm(segment.hands)
        ) + 0.1 * abs(segment.press)
        return FALL_COST * max(lost, 0.0) + BAR_COST * float(missed.sum()) + soft + 0.1 * size


def _skip_ahead(
    tracker: Tracker, ref: Reference, beam: list[Elite], scorer: Scorer, ramp: int, start_before: int, T: int
) -> tuple[list[Elite], int, int]:
    """``(beam, frame to search on from, frame of the next such check)`` after the beam's best elite stood clean over
    its segment and lookahead. Its continuation with no further offset is simulated to the end: standing with no
    frame past a bar, the search is done (frame ``T``); else the search resumes ``start_before`` frames before the
    continuation's drift onset from the best elite advanced there alone, or, where that is no later than the elite's
    frame, from the beam as it was (and checks again only past that onset). Why: stretches the teacher walks unaided
    are not searched, so the budget goes to the windows that fall (BENCHMARKS.md, the robot-alone table)."""
    best = beam[0]
    tracker.restore(best.snapshot)
    tracker.ref = GuidedReference(ref, best.segments, ramp)
    s0 = tracker.t
    tracker.run(T)
    if tracker.fell_at is None and tracker.t >= T and scorer.cost(tracker, s0, T, Segment(s0, T)) < BAR_COST:
        return [best], T, T
    onset = drift_onset(ref, np.asarray(tracker.rec["qpos"][s0:]), tracker.fell_at, scorer.objects, since=s0)
    resume = onset - start_before
    if resume <= s0:
        return beam, s0, onset
    tracker.restore(best.snapshot)
    tracker.run(resume)
    return [Elite(tracker.snapshot(), best.segments, best.cost)], resume, onset


def search(
    scene: Scene,
    ref: Reference,
    make_controller: Callable[[], WholeBodyController],
    qpos0: np.ndarray,
    qvel0: np.ndarray,
    nominal: Rollout,
    config: SearchConfig = SearchConfig(),
    *,
    contact_links: tuple[str, ...] = (),
    objects: dict[str, np.ndarray] | None = None,
    max_frames: int | None = None,
    workers: int = 1,
    perturb: Callable[[int, mujoco.MjData], None] | None = None,
) -> SearchResult | None:
    """The module docstring's search from the ``nominal`` rollout's drift onset; None when it did not fall.
    ``objects``: the objects' reference tracks ({name: (T, 7)}), whose loss the children's cost counts;
    ``max_frames``: its budget of simulated control frames (default :func:`frame_budget`); ``workers``: processes
    the children are simulated in (:mod:`physicalize.search.children`; the same result for any number);
    ``perturb``: every tracker's (:class:`physicalize.guidance.ObjectGuidance`, a measurement, never data)."""
    if nominal.fell_at is None:
        return None
    cpu0, fps, T = time.process_time(), ref.fps, ref.frames
    L, H = max(int(round(config.segment_s * fps)), 1), int(round(config.lookahead_s * fps))
    ramp = int(round(config.ramp_s * fps))
    scorer = Scorer.of(scene, ref, objects)
    start_before = int(round(config.start_before_s * fps))
    start = max(0, drift_onset(ref, nominal.qpos, nominal.fell_at, scorer.objects) - start_before)
    rng = np.random.default_rng(config.seed)
    sigma = np.array([config.com_sigma_m] * 2 + [config.step_sigma_m] * 2)
    held_sigma = np.array([config.hands_sigma_m] * 3 + [config.press_sigma])
    tracker = Tracker(scene, ref, make_controller(), qpos0, qvel0, contact_links=contact_links, perturb=perturb)
    tracker.run(start)
    beam, children, s, next_check = [Elite(tracker.snapshot(), (), 0.0)], 0, start, 0
    budget = frame_budget(config, T, fps) if max_frames is None else max_frames
    with Children(tracker, scorer, ramp, H, workers) as pool:
        while s < T and tracker.steps + pool.frames < budget:
            stop = min(s + L, T)
            jobs = []
            for elite in beam:
                for c in range(config.children):
                    seg = Segment(s, stop)
                    if c:
                        theta = rng.normal(0.0, sigma)
                        held = rng.normal(0.0, held_sigma) if scorer.objects else np.zeros(4)
                        seg = Segment(s, stop, tuple(theta[:2]), tuple(theta[2:]), tuple(held[:3]), float(held[3]))
                    jobs.append((elite.snapshot, elite.segments + (seg,)))
            offspring = [Elite(snap, segs, cost) for (_, segs), (snap, cost) in zip(jobs, pool.run(jobs))]
            children += len(offspring)
            beam = sorted(offspring, key=lambda e: e.cost)[: config.beam]
            s = stop
            if beam[0].cost < BAR_COST and next_check <= s < T:  # the best stands clean: search on where it fails
                beam, s, next_check = _skip_ahead(tracker, ref, beam, scorer, ramp, start_before, T)
        frames, remote_cpu = tracker.steps + pool.frames, pool.cpu_s
    best = beam[0].segments
    guided = GuidedReference(ref, best, ramp)
    final = Tracker(scene, guided, make_controller(), qpos0, qvel0, contact_links=contact_links, perturb=perturb)
    final.run(T)
    cpu_s = time.process_time() - cpu0 + remote_cpu
    return SearchResult(final.rollout(), best, cpu_s, remote_cpu, children, frames, start)
