"""One run of a stage, the recipe every stage command follows around its algorithm::

    run = StageRun(out, fingerprint(...))          # datasets/<NAME>/<stage>, and what the output depends on
    if not overwrite and (done := run.finished()):  # a finished run on the same input and options
        return {**done, "up_to_date": True}
    run.check(overwrite)                           # may this run write `out`? (one line if not; nothing written)
    clips = read(...)                              # the input, read and validated
    run.begin(overwrite)                           # the resume record
    results = run.map(per_clip, clips, key=..., jobs=..., executor=...)   # resumable, local or Ray
    ... write_dataset(run.out, ..., overwrite=run.replaces) ... logs, figures ...
    return run.finish(report, dataset_written=...)  # the report; the done mark, written last

**Finished** means ``logs/<stage>/report.json`` records this run's fingerprint (:mod:`pipeline.stage.state`)
and the dataset it says was written is there. **Resume**: :meth:`StageRun.begin` records the fingerprint in
``.work/<stage>/run.json``; every clip's result is kept in ``.work/<stage>/clips/`` as it finishes
(one pickle per clip, written atomically); :meth:`StageRun.finish` writes the reports and only then removes the work
folder. A run killed at any point (SIGKILL included: every file is written atomically, the dataset by a
rename) and started again with the same input and options finds its own ``run.json``, takes the finished
clips from the cache, may replace the dataset it had already written, and ends with the same dataset as an
uninterrupted run. ``--overwrite`` starts afresh (the cache too: code may have changed since).
"""

from __future__ import annotations

import hashlib
import pickle
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from pipeline.dataset.chain import stale_reason
from pipeline.dataset.write import check_target
from pipeline.stage.atomic import write_json_atomic, write_pickle_atomic
from pipeline.stage.executor import map_ordered
from pipeline.stage.paths import logs_dir, work_dir
from pipeline.stage.state import KEY, up_to_date

T = TypeVar("T")
R = TypeVar("R")


def digest(*parts: object) -> str:
    """A short hex digest of ``parts`` (arrays by their bytes, anything else by its ``str``): a clip's cache key."""
    h = hashlib.sha256()
    for p in parts:
        h.update(p.tobytes() if hasattr(p, "tobytes") else str(p).encode())
        h.update(b"|")
    return h.hexdigest()[:16]


@dataclass(frozen=True)
class _Cached:
    """``fn(item)``, taken from the cache file when an earlier (interrupted) run finished it."""

    fn: Callable

    def __call__(self, job: tuple[Path, object]):
        path, item = job
        if path.is_file():
            return pickle.loads(path.read_bytes())
        result = self.fn(item)
        write_pickle_atomic(path, result)
        return result


class StageRun:
    """One run of a stage writing the dataset ``out`` (see the module docstring)."""

    def __init__(self, out: Path, fingerprint: str):
        self.out, self.fingerprint = Path(out), fingerprint
        self.logs, self.work = logs_dir(self.out), work_dir(self.out)
        self.clips = self.work / "clips"
        self.replaces = False  # set by begin(): whether write_dataset may replace an existing `out`
        self._said_stale = False

    def finished(self) -> dict | None:
        """The report of a finished run with this fingerprint whose dataset (if it wrote one) is in place."""
        report = up_to_date(self.logs / "report.json", self.fingerprint)
        if report is None or (report.get("dataset_written", True) and not self.out.is_dir()):
            return None
        return None if stale_reason(self.out) else report  # made from an upstream since rewritten: redo it

    def check(self, overwrite: bool) -> bool:
        """Whether this run may write ``out``, writing nothing: an existing dataset is replaced only with
        ``overwrite``, when this same run (same fingerprint, interrupted) wrote it, or when it is stale (made from
        an upstream dataset since rewritten: :mod:`pipeline.dataset.chain`); otherwise one
        :class:`~pipeline.errors.InputError` line. A stage that reads the user's input calls it before reading,
        and :meth:`begin` after, so a refused input leaves no resume record behind."""
        own = up_to_date(self.work / "run.json", self.fingerprint) is not None
        stale = not overwrite and not own and self.out.is_dir() and stale_reason(self.out)
        check_target(self.out, overwrite or own or bool(stale))
        if stale and not self._said_stale:
            print(f"{self.out}: {stale}: redoing it")
            self._said_stale = True
        return own or bool(stale)

    def begin(self, overwrite: bool) -> None:
        """Claim ``out`` for this run (:meth:`check`) and record the fingerprint in ``.work/<stage>/run.json``."""
        may_replace = self.check(overwrite)
        if overwrite or up_to_date(self.work / "run.json", self.fingerprint) is None:
            shutil.rmtree(self.work, ignore_errors=True)  # a fresh run, or another run's leftovers
        write_json_atomic(self.work / "run.json", {KEY: self.fingerprint})
        self.replaces = overwrite or may_replace

    def map(
        self,
        fn: Callable[[T], R],
        items: Sequence[T],
        *,
        key: Callable[[int, T], str],
        jobs: int = 1,
        executor: str = "local",
        desc: str = "",
    ) -> list[R]:
        """``[fn(item) ...]`` in order on the executor (:mod:`pipeline.stage.executor`), each result kept in the
        cache under ``key(index, item)`` and taken from it when an interrupted run had finished it."""
        jobs_ = [(self.clips / f"{key(k, item)}.pkl", item) for k, item in enumerate(items)]
        self.clips.mkdir(parents=True, exist_ok=True)
        return map_ordered(_Cached(fn), jobs_, jobs=jobs, executor=executor, desc=desc)

    def finish(self, report: dict, *, dataset_written: bool) -> dict:
        """Write ``report`` (with the fingerprint) into the dataset and, last, into ``logs/<stage>/`` (the done
        mark), then drop the work folder. Without a dataset, an old one at ``out`` is removed (it is not this
        run's output)."""
        report = {**report, KEY: self.fingerprint, "dataset_written": dataset_written}
        if dataset_written:
            write_json_atomic(self.out / "report.json", report)
        elif self.out.is_dir():
            shutil.rmtree(self.out)
        write_json_atomic(self.logs / "report.json", report)
        shutil.rmtree(self.work, ignore_errors=True)
        return report
