"""Annealed object guidance inside the search (:func:`search`): the beam search (:mod:`physicalize.search.beam`) run
level by level with the held objects pulled towards their reference tracks by
:class:`physicalize.guidance.ObjectGuidance` at a falling scale (:attr:`physicalize.search.beam.SearchConfig.guidance`;
:data:`LEVELS`, 1.0 -> 0.3, as measured), then with none. Each level searches on top of the segments the levels
before it chose (its first elite carries them, its nominal rollout is theirs at its own scale); only the last,
unguided level makes data: its rollout is validated as every rollout is, the segments of every level recorded.

Why: a search with no guidance looks for a walk and a push at once, from a teacher that loses its object first; with
the object held on its track the same search finds a walk that carries the push (every shared box slide stood to the
end at scale 1, BENCHMARKS.md), and the levels below hand the push back to the robot a step at a time, as ResMimic (a
virtual object force curriculum) and SPIDER (virtual contact constraints annealed to zero) do. Each guided level
spends :attr:`~physicalize.search.beam.SearchConfig.guided_share` of the budget, the unguided one the rest.

Measured (BENCHMARKS.md; ``bench_physicalize_real.py --anneal``): on the 20 shared takes the same verdicts, but two box
slides that the plain search left losing their box stand to the end with it on its track, failing only 2-3 frames of
a landing ankle past its range; on ``make corpus`` 96 of 100 valid against the plain search's 100 (four Carry clips
keep a rollout one joint-limit frame short). So it is not the stage's default
(:attr:`~physicalize.search.beam.SearchConfig.guidance` is empty): the lead to follow on real takes, not yet data.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from physicalize.guidance import ObjectGuidance
from physicalize.reference import Reference
from physicalize.rollout import Rollout, simulate
from physicalize.search import beam
from physicalize.search.beam import SearchConfig, SearchResult
from physicalize.search.guide import GuidedReference, Segment
from physicalize.wbc import WholeBodyController
from pipeline.scene import Scene

LEVELS: tuple[float, ...] = (1.0, 0.3)  # the guidance's scales before the unguided level, as measured


@dataclass(frozen=True)
class Level:
    """One level of the annealing as the figures record it: the guidance's ``scale`` (0: none), when its nominal
    rollout and its search's best fell [s] (None: stood), the segments it added and the control frames it simulated."""

    scale: float
    nominal_fell_at_s: float | None
    fell_at_s: float | None
    segments: int
    frames: int

    def as_dict(self) -> dict:
        return asdict(self)


def guided_objects(scene: Scene, objects: dict[str, np.ndarray] | None) -> dict[str, np.ndarray]:
    """The free objects of ``objects`` (those a guidance can hold: a fixed one is the world's)."""
    return {n: p for n, p in (objects or {}).items() if n in scene.object_qpos_adr}


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
) -> tuple[SearchResult | None, list[Level]]:
    """``(result, levels)``: the module docstring's levels, then the unguided search from the rollout of their segments
    (from ``nominal`` where no guided level searched); result None when no level searched (never for a ``nominal``
    that fell: the unguided level then searches at least from it). With no free object, no
    :attr:`~physicalize.search.beam.SearchConfig.guidance` or a fixed ``perturb`` (a measurement:
    :func:`physicalize.clip.physicalize_clip`'s ``guide``) this is :func:`physicalize.search.beam.search`, no level."""
    held = guided_objects(scene, objects)
    kw = {"contact_links": contact_links, "objects": objects, "workers": workers}
    budget = beam.frame_budget(config, ref.frames, ref.fps) if max_frames is None else max_frames
    if perturb is not None or not held or not config.guidance:
        plain = beam.search(
            scene, ref, make_controller, qpos0, qvel0, nominal, config, max_frames=budget, perturb=perturb, **kw
        )
        return plain, []
    cpu0, ramp, fps = time.process_time(), int(round(config.ramp_s * ref.fps)), ref.fps
    segments: tuple[Segment, ...] = ()
    levels, spent, worker_cpu, children, start = [], 0, 0.0, 0, None
    for scale in (*config.guidance, 0.0):
        guidance = ObjectGuidance.of(scene, held, fps, scale) if scale > 0 else None
        if segments or scale > 0:
            guided = GuidedReference(ref, segments, ramp)
            nominal = simulate(
                scene, guided, make_controller(), qpos0, qvel0, contact_links=contact_links, perturb=guidance
            )
        share = budget - spent if scale == 0 else min(int(config.guided_share * budget), budget - spent)
        found = beam.search(
            scene,
            ref,
            make_controller,
            qpos0,
            qvel0,
            nominal,
            config,
            max_frames=share,
            perturb=guidance,
            segments=segments,
            **kw,
        )
        roll, frames, added = nominal, 0, 0
        if found is not None:
            roll, frames, added = found.rollout, found.frames, len(found.segments) - len(segments)
            spent, worker_cpu, children = (
                spent + found.frames,
                worker_cpu + found.worker_cpu_s,
                children + found.children,
            )
            segments, start = found.segments, found.start if start is None else start
        levels.append(Level(scale, _seconds(nominal.fell_at, fps), _seconds(roll.fell_at, fps), added, frames))
    if start is None:
        return None, levels
    cpu = time.process_time() - cpu0 + worker_cpu
    return SearchResult(roll, segments, cpu, worker_cpu, children, spent, start), levels


def _seconds(frame: int | None, fps: float) -> float | None:
    return None if frame is None else frame / fps
