"""What every stage's command does around its algorithm.

* :mod:`~pipeline.stage.run` -- the recipe: up to date, claim the output, the per-clip map with its resume
  cache, the done mark (a run killed anywhere resumes to the same dataset);
* :mod:`~pipeline.stage.executor` -- where the per-clip work runs: this process, local processes, or Ray;
* :mod:`~pipeline.stage.state` -- fingerprints: what a stage's output depends on;
* :mod:`~pipeline.stage.paths` -- where a stage reads and writes (``datasets/<NAME>/<stage>/``, logs, work);
* :mod:`~pipeline.stage.atomic` -- files written whole or not at all;
* :mod:`~pipeline.stage.lock` -- one writer per dataset (``datasets/<NAME>/.lock``);
* :mod:`~pipeline.stage.inspect_log`, :mod:`~pipeline.stage.figure` -- MCAP inspection logs and PNG figures.
"""
