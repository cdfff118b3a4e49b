"""Where a stage's per-clip work runs: in this process, in local worker processes, or on a Ray cluster.

:func:`map_ordered` applies a module-level function to every item and returns the results in the
items' order, whatever order they finish in, with a progress bar. The executors:

* ``local`` -- ``jobs`` worker processes (``concurrent.futures``; ``jobs <= 1``: this process, no pool);
* ``ray`` -- one Ray task (1 CPU) per item on the cluster at ``$RAY_ADDRESS`` (``ray start --head`` on
  one machine, ``ray start --address=...`` on the others), or on a local Ray instance of ``jobs`` CPUs
  when ``$RAY_ADDRESS`` is unset. The workers import the same packages (install the toolkit on every
  node) and read and write the per-clip resume cache in the dataset folder (:mod:`pipeline.stage.cache`),
  so that folder must be on a file system every node shares.

The function must be deterministic per item (the stages are): then every executor gives the same results.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import TypeVar

from tqdm import tqdm

from pipeline.errors import InputError

EXECUTORS = ("local", "ray")

T = TypeVar("T")
R = TypeVar("R")


def check_executor(executor: str, jobs: int) -> None:
    """An unknown executor or a job count below 1 is an :class:`InputError` (one line, before any work)."""
    if executor not in EXECUTORS:
        raise InputError(executor, "--executor", f"unknown executor; available: {', '.join(EXECUTORS)}")
    if jobs < 1:
        raise InputError(jobs, "--jobs", "must be at least 1")


def map_ordered(
    fn: Callable[[T], R], items: Sequence[T], *, jobs: int = 1, executor: str = "local", desc: str = ""
) -> list[R]:
    """``[fn(item) for item in items]`` on the ``executor`` (see the module docstring)."""
    check_executor(executor, jobs)
    bar = tqdm(total=len(items), desc=desc, unit="clip")
    try:
        if executor == "ray":
            return _ray(fn, items, jobs, bar)
        if jobs <= 1 or len(items) <= 1:
            out = []
            for item in items:
                out.append(fn(item))
                bar.update()
            return out
        return _processes(fn, items, jobs, bar)
    finally:
        bar.close()


def _processes(fn, items, jobs, bar) -> list:
    out: list = [None] * len(items)
    with ProcessPoolExecutor(max_workers=min(jobs, len(items))) as pool:
        futures = {pool.submit(fn, item): k for k, item in enumerate(items)}
        for f in as_completed(futures):
            out[futures[f]] = f.result()
            bar.update()
    return out


def _call(fn, item):
    """``fn(item)``: a Ray task (Ray remotes functions, not callable objects)."""
    return fn(item)


def _ray(fn, items, jobs, bar) -> list:
    import ray  # ~1 s to import, and only a cluster run needs it

    started = not ray.is_initialized()
    if started:
        address = os.environ.get("RAY_ADDRESS")
        ray.init(address=address, **({} if address else {"num_cpus": jobs}), log_to_driver=False)
    try:
        task = ray.remote(num_cpus=1)(_call)
        pending = {task.remote(fn, item): k for k, item in enumerate(items)}
        out: list = [None] * len(items)
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                out[pending.pop(ref)] = ray.get(ref)
                bar.update()
        return out
    finally:
        if started:
            ray.shutdown()
