"""Where a beam step's children are simulated (:func:`physicalize.search.beam.search`): in the search's own tracker,
or over ``workers`` worker processes, each with its own copy of that tracker.

A child: restore its elite's snapshot, guide the reference with the elite's segments and its own
(:class:`physicalize.search.guide.GuidedReference`), run to its segment's end (snapshot there), run the lookahead and
score it (:meth:`physicalize.search.beam.Scorer.cost`). The children's offsets are drawn in the search's process, in
one order, and a restored tracker continues bit for bit (:class:`physicalize.rollout.Tracker`), so a seed gives the
same beam, the same segments and the same rollout with any number of workers (``tests/test_search_children.py``).

Why processes: the QP teacher is Python and numpy, one core per child (~4 ms of CPU a control frame), and a beam
step's 36 children are independent. Why ``fork``: a worker inherits the scene (its ``MjSpec`` does not pickle), the
controller and the reference as they are when the pool starts; only snapshots, segments, costs and counts cross
between processes (a few kB a child). A child's frames and CPU-seconds come back with it, so the search's budget
(a count of frames) and its cost (CPU-seconds, every process's) are the same as run here. Where ``fork`` is not
available (Windows) the children run here.
"""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from typing import TYPE_CHECKING

from physicalize.rollout import Snapshot, Tracker
from physicalize.search.guide import GuidedReference, Segment

if TYPE_CHECKING:
    from physicalize.search.beam import Scorer

Job = tuple[Snapshot, tuple[Segment, ...]]  # an elite's snapshot and the child's segments (the elite's, then its own)

_WORKER: tuple | None = None  # (tracker, scorer, ramp, lookahead) of this worker process


def simulate_child(
    tracker: Tracker, scorer: Scorer, ramp: int, lookahead: int, start: Snapshot, segments: tuple[Segment, ...]
) -> tuple[Snapshot, float]:
    """The child whose last segment is ``segments[-1]``, simulated on ``tracker`` from ``start`` (module docstring):
    its snapshot at that segment's end and its cost over the segment and the lookahead."""
    seg = segments[-1]
    tracker.restore(start)
    tracker.ref = GuidedReference(scorer.ref, segments, ramp)
    tracker.run(seg.stop)
    snap = tracker.snapshot()
    tracker.run(seg.stop + lookahead)
    return snap, scorer.cost(tracker, seg.start, seg.stop + lookahead, seg)


def _start(tracker: Tracker, scorer: Scorer, ramp: int, lookahead: int) -> None:
    global _WORKER
    _WORKER = (tracker, scorer, ramp, lookahead)


def _remote(job: Job) -> tuple[tuple[Snapshot, float], int, float]:
    """A child in a worker: it, the control frames it simulated and its CPU-seconds."""
    tracker, scorer, ramp, lookahead = _WORKER
    steps, cpu0 = tracker.steps, time.process_time()
    child = simulate_child(tracker, scorer, ramp, lookahead, *job)
    return child, tracker.steps - steps, time.process_time() - cpu0


class Children:
    """Simulates a beam step's children on ``tracker`` (``workers`` <= 1) or over ``workers`` forked processes;
    :attr:`frames` and :attr:`cpu_s` count what the workers simulated (the tracker's own count the rest). A context
    manager: the pool ends with the search."""

    def __init__(self, tracker: Tracker, scorer: Scorer, ramp: int, lookahead: int, workers: int = 1):
        if workers < 1:
            raise ValueError(f"search workers: must be >= 1, got {workers}")
        self.local = (tracker, scorer, ramp, lookahead)
        self.frames, self.cpu_s = 0, 0.0
        forkable = "fork" in multiprocessing.get_all_start_methods()
        self.pool = None
        if workers > 1 and forkable:
            context = multiprocessing.get_context("fork")
            self.pool = ProcessPoolExecutor(workers, mp_context=context, initializer=_start, initargs=self.local)

    def run(self, jobs: list[Job]) -> list[tuple[Snapshot, float]]:
        """Each child's snapshot and cost (:func:`simulate_child`), in the order of ``jobs``."""
        if self.pool is None:
            return [simulate_child(*self.local, *job) for job in jobs]
        out = []
        for child, frames, cpu_s in self.pool.map(_remote, jobs):
            out.append(child)
            self.frames, self.cpu_s = self.frames + frames, self.cpu_s + cpu_s
        return out

    def __enter__(self) -> Children:
        return self

    def __exit__(self, *exc) -> None:
        if self.pool is not None:
            self.pool.shutdown()
