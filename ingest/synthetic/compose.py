"""COMPOSED long-horizon demonstrations: one clip strings task segments with the walking between them.

:func:`composed` makes one SYNTHETIC human clip (task ``"Chain"``, source ``synthetic:Chain:<A>-<B>-...``) that
performs the tasks of ``order`` one after the other, e.g. ``("Carry", "SitStand", "Push")``: pick up a small box,
carry it, put it down, walk to a chair, turn, sit, stand up, walk to a large box, push it. Every segment is the
single demonstration's own motion (:data:`ingest.synthetic.tasks.SEGMENTS`, the same timings and geometry, the
seed's jitter of its object), placed in the world by a :class:`~ingest.synthetic.tasks.Frame`:

* the first segment is its single demonstration from the start: standing 0.3 s at the origin facing +x, a
  straight walk to its approach stance;
* every later segment starts where the previous one left the walker standing, at ``(c, yaw)``: its approach
  stance is ``d`` = 1.1-1.7 m away (uniform) in the direction ``yaw + theta``, facing that way, and its object
  stands where its single demonstration has it relative to that stance. The walk there (phase ``approach``) is
  one :meth:`~ingest.synthetic.gait.GaitPlan.walk` (step period 0.55 s, swing 0.42 s, 6 cm clearance): turning
  on the spot by at most 45 deg a step, then straight steps of at most 0.55 m, then a closing step; e.g. a 90 deg
  turn and 1.4 m take 2 + 3 + 1 steps, ~3.7 s. ``theta`` is +-90 deg (+-9 deg jitter) after a segment that
  leaves its object in front of the walker (PickUp, Carry, Push), 0 or +-45 deg after SitStand (the chair is
  behind it); the seed orders the two preferred turns, then the others are tried
  (:data:`TURNS`): the first layout kept is the first whose walker path keeps :data:`CLEAR_M` outside every
  other object's footprint (:data:`RADIUS`, at its pose at the time: before its segment where it started,
  after it where the segment left it) and whose objects stand :data:`GAP_M` apart beyond their radii; the
  walker leaving the object it just handled (nearer than that) may come no more than :data:`LEAVE_TOL_M` nearer.
* a PickUp that is not the last segment holds the box 1.0 s and sets it back down where it was (put_down,
  settle, release, rise, stand: 3.4 s, as Carry's); the last one holds it 3 s and the clip ends holding it.

Objects: one per segment, ``object``, ``object_2``, ... in segment order, each present (resting at its start
pose, or where its segment left it) for the whole clip, and touched in its own segment only: its
``ObjectTrack.contact`` and the joint contact flags (wrists on a box, pelvis and hips on the seat) are those of
the single demonstration restricted to the segment's time span (from the start of its approach walk to its
end). Phases: each segment's phases (``approach`` and the single demonstration's; the first segment starts
with ``stand``) named ``<k>:<task>/<phase>`` (``k`` from 1), so ``2:SitStand/seated``; consecutive phases may
overlap, never leave gaps. Timings: a segment is as long as its single demonstration minus its 0.3 s stand and
approach walk, plus its approach from the previous segment (~2.5-4 s): ``("Carry", "SitStand", "Push")``
~30 s, ``("PickUp", "SitStand")`` ~20 s.

Objects per clip: one per segment. Several objects per clip go through ``lessmimic retarget`` and ``lessmimic
physicalize`` (each object a free body of the scene, the grasp schedule per object, per-object dataset columns
``object``, ``object_2``, ...); a dataset, though, holds clips with one number of objects
(:mod:`pipeline.dataset.objects`), so the orders of a corpus (:data:`CHAIN_ORDERS`) all have the same length and
chains do not mix with the single tasks (one object) in one dataset. The corpus strings pairs: every transition
``A -> B`` between two different tasks once per 12 seeds, the shortest composed clips (~17-22 s): physicalize
judges a clip as a whole, with one teacher gain set for all of it (measured with the base teacher: 4 of the 12
pairs of seeds 0-11 valid, none of 9 chains of 3 or 4 tasks).
"""

from __future__ import annotations

import copy
import itertools
from dataclasses import dataclass, replace

import numpy as np

from ingest.synthetic.body import Channels, SyntheticDemo, evaluate, make_demo
from ingest.synthetic.gait import GaitPlan, heading
from ingest.synthetic.skeleton import PELVIS_FWD
from ingest.synthetic.tasks import SEGMENTS, Frame, Part, time_grid

CHAIN = "Chain"
# The training orders of a corpus (``synthetic:<seeds>:Chain``): seed s makes CHAIN_ORDERS[s % 12], every ordered
# pair of two different tasks (in the generator's task order), two objects per clip.
CHAIN_ORDERS: tuple[tuple[str, ...], ...] = tuple(itertools.permutations(SEGMENTS, 2))
TURN_STEP = np.pi / 4  # at most this much turn per step on the spot
MAX_STEP = 0.55  # straight steps of at most this
WALK = dict(period=0.55, swing=0.42, clearance=0.06)  # the walks between segments (as carrying)
WALK_M = (1.1, 1.7)  # the approach stance this far from where the previous segment ended (uniform)
JITTER = np.deg2rad(9.0)  # the turn towards the next segment: +- this around its nominal value
# Nominal turns towards the next segment after each task: the seed orders the first two, then the rest follow.
TURNS = {
    "PickUp": (np.pi / 2, -np.pi / 2, 3 * np.pi / 4, -3 * np.pi / 4),
    "Carry": (np.pi / 2, -np.pi / 2, 3 * np.pi / 4, -3 * np.pi / 4),
    "Push": (np.pi / 2, -np.pi / 2, 3 * np.pi / 4, -3 * np.pi / 4),
    "SitStand": (np.pi / 4, -np.pi / 4, 0.0, np.pi / 2, -np.pi / 2),
}
RADIUS = {"PickUp": 0.25, "Carry": 0.25, "SitStand": 0.35, "Push": 0.45}  # object footprint radius [m]
CLEAR_M = 0.35  # the walker's pelvis path keeps this far outside other objects' footprints
GAP_M = 0.30  # objects stand this far apart beyond their footprints
LEAVE_TOL_M = 0.03  # leaving the object it just handled, the walker may come this much nearer (turns < 90 deg)
PUT_BACK_HOLD_S = 1.0  # a PickUp that is not last holds the box this long before setting it back down


@dataclass(frozen=True)
class Placed:
    """A segment placed in the clip: its task, when its approach walk starts and ends, its :class:`Part`,
    and the walker's path through its walk and motion (N, 2) (:func:`_path`)."""

    task: str
    start: float
    walk_end: float
    part: Part
    path: np.ndarray


def chain_demo(fps: float = 30.0, seed: int = 0) -> SyntheticDemo:
    """The corpus's composed demonstration of ``seed``: the order ``CHAIN_ORDERS[seed % 12]`` from the random
    stream ``default_rng([seed, 4])`` (the single demonstrations of a seed use the streams 0-3)."""
    order = CHAIN_ORDERS[seed % len(CHAIN_ORDERS)]
    return composed(np.random.default_rng([seed, len(SEGMENTS)]), float(fps), order)


def check_order(order) -> tuple[str, ...]:
    """``order`` as a tuple of at least two known task names; else a one-line ``ValueError``."""
    order = tuple(order)
    if len(order) < 2:
        raise ValueError(f"a chain strings at least 2 tasks, got {order}")
    if unknown := [t for t in order if t not in SEGMENTS]:
        raise ValueError(f"unknown task {unknown[0]!r} in chain {order} (known: {', '.join(SEGMENTS)})")
    return order


def chain_source(order: tuple[str, ...]) -> str:
    """``synthetic:Chain:<A>-<B>-...``."""
    return f"synthetic:{CHAIN}:{'-'.join(order)}"


def _turn(centre: np.ndarray, yaw0: float, yaw1: float) -> list[tuple]:
    """Stances turning on the spot from ``yaw0`` to ``yaw1`` in equal steps of at most :data:`TURN_STEP`."""
    n = int(np.ceil(abs(yaw1 - yaw0) / TURN_STEP - 1e-9))
    return [(centre, yaw0 + (yaw1 - yaw0) * k / n) for k in range(1, n + 1)]


def walk_to(g: GaitPlan, t: float, centre: np.ndarray, yaw: float) -> float:
    """Walk from the plan's stance to ``(centre, yaw)`` starting at ``t``: turn on the spot to face it, step
    straight to it, turn on the spot to ``yaw`` (one walk: no stop between; the first foot is on the side of
    the first turn). Returns when the walker stands still."""
    d = np.asarray(centre, float) - g.centre
    psi = g.yaw + float(np.angle(np.exp(1j * (np.arctan2(d[1], d[0]) - g.yaw))))  # the nearest equivalent heading
    n = max(1, int(np.ceil(np.linalg.norm(d) / MAX_STEP - 1e-9)))
    stances = _turn(g.centre, g.yaw, psi) + [(g.centre + d * k / n, psi) for k in range(1, n + 1)]
    stances += _turn(np.asarray(centre, float), psi, yaw)
    return g.walk(t, stances, first=0 if psi >= g.yaw else 1, **WALK)


def _path(g: GaitPlan, first_key: int) -> np.ndarray:
    """The walker's path (the pelvis keys' stance centres: between the ankles) from key ``first_key`` on (the
    previous segment's end included), every <= 0.1 m."""
    keys = np.array([xy - PELVIS_FWD * heading(yaw) for _, xy, yaw in g.keys[max(first_key - 1, 0) :]])
    out = [keys[:1]]
    for a, b in zip(keys[:-1], keys[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / 0.1)))
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.concatenate(out)


def clearance(placed: list[Placed]) -> float:
    """The least margin (m; negative: a collision) of the layout (module docstring): every walker path against
    every other segment's object at its pose at that time, and every two objects' rest poses."""
    worst = np.inf
    for i, obj in enumerate(placed):
        need = RADIUS[obj.task] + CLEAR_M
        for j, seg in enumerate(placed):
            if j == i:
                continue
            d = np.linalg.norm(seg.path - obj.part.rest[0 if j < i else 1], axis=1)
            start_near = d[0] - LEAVE_TOL_M if j == i + 1 else np.inf  # leaving the object it just handled
            worst = min(worst, float(d.min() - min(need, start_near)))
        for other in placed[i + 1 :]:
            gap = min(np.linalg.norm(a - b) for a in obj.part.rest for b in other.part.rest)
            worst = min(worst, float(gap - RADIUS[obj.task] - RADIUS[other.task] - GAP_M))
    return worst


def _segment(g: GaitPlan, ch: Channels, t: float, task: str, params, frame: Frame, first: bool, last: bool) -> Placed:
    """Walk to the segment's approach stance in ``frame`` from ``t`` (the first segment: straight, as its single
    demonstration) and add its motion (module docstring)."""
    seg, k0 = SEGMENTS[task], len(g.keys)
    stance = frame.point(*seg.stance(params))
    t1 = g.walk_straight(t, stance) if first else walk_to(g, t, stance, frame.yaw)
    options = {"put_back": True, "hold": PUT_BACK_HOLD_S} if task == "PickUp" and not last else {}
    part = seg.build(t1, g, ch, frame, params, **options)
    return Placed(task, t, t1, part, _path(g, k0))


def _next(rng, g: GaitPlan, ch: Channels, t: float, task: str, params, placed: list[Placed], last: bool):
    """The next segment placed by the first clear layout (module docstring): (gait plan, channels, Placed)."""
    d, jitter = rng.uniform(*WALK_M), rng.uniform(-JITTER, JITTER)
    turns = list(TURNS[placed[-1].task])
    turns[:2] = [turns[i] for i in rng.permutation(2)]
    local = SEGMENTS[task].stance(params)
    margins = []
    for theta in turns:  # the approach stance d ahead along yaw; the frame's origin is where local (0, 0) lands
        yaw = g.yaw + theta + jitter
        origin = g.centre + d * heading(yaw) - Frame(yaw=yaw).point(*local)
        trial_g, trial_ch = copy.deepcopy(g), copy.deepcopy(ch)
        frame = Frame((float(origin[0]), float(origin[1])), yaw)
        seg = _segment(trial_g, trial_ch, t, task, params, frame, first=False, last=last)
        margins.append(clearance([*placed, seg]))
        if margins[-1] >= 0.0:
            return trial_g, trial_ch, seg
    raise ValueError(f"no clear layout for {task} after {[p.task for p in placed]} (best margin {max(margins):.2f} m)")


def composed(rng: np.random.Generator, fps: float, order: tuple[str, ...]) -> SyntheticDemo:
    """One composed demonstration of the tasks ``order`` (module docstring), task ``"Chain"``, source
    :func:`chain_source`. The same ``rng`` state, ``fps`` and ``order`` give bit-identical arrays."""
    order = check_order(order)
    g, ch = GaitPlan((0.0, 0.0), 0.0), Channels()
    placed: list[Placed] = []
    for k, task in enumerate(order):
        params, last = SEGMENTS[task].draw(rng), k == len(order) - 1
        if k == 0:
            placed.append(_segment(g, ch, 0.3, task, params, Frame(), first=True, last=last))
        else:
            g, ch, seg = _next(rng, g, ch, placed[-1].part.end, task, params, placed, last)
            placed.append(seg)
    return _assemble(fps, order, g, ch, placed)


def _assemble(fps: float, order: tuple[str, ...], g: GaitPlan, ch: Channels, placed: list[Placed]) -> SyntheticDemo:
    """Evaluate the body over the whole clip; each segment's object, wrist targets and contact flags within
    its time span; the clip labelled ``Chain`` with its order in the source and the phase names."""
    ts = time_grid(placed[-1].part.end, fps)
    body = evaluate(ts, g, ch)
    targets = np.zeros((len(ts), 2, 3))
    objects, contacts, phases = [], {}, []
    for k, p in enumerate(placed):
        obj, target, flags = p.part.finish(body)
        last = k == len(placed) - 1  # its span runs to the clip's last frame (the grid may pass the end by < 1/2 frame)
        span = (ts >= p.start - 1e-9) & ((ts <= p.part.end + 1e-9) | last)
        targets[ts >= p.start - 1e-9] = target[ts >= p.start - 1e-9]  # later segments take over
        objects.append({**obj, "name": "object" if k == 0 else f"object_{k + 1}", "contact": obj["contact"] & span})
        for joint, f in flags.items():
            contacts[joint] = contacts.get(joint, np.zeros(len(ts), bool)) | (f & span)
        own = ([("stand", 0.0, p.start)] if k == 0 else []) + [("approach", p.start, p.walk_end), *p.part.phases]
        phases += [(f"{k + 1}:{p.task}/{name}", a, b) for name, a, b in own]
    demo = make_demo(CHAIN, fps, body, targets, objects, phases, contacts)
    source = chain_source(order)
    clip = replace(demo.clip, source=source, objects=tuple(replace(o, source=source) for o in demo.clip.objects))
    return replace(demo, clip=clip)
