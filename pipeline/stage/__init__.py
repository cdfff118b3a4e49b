"""What every stage's command does around its algorithm.

* :mod:`~pipeline.stage.paths` -- where a stage reads and writes (``datasets/<NAME>/<stage>/``, logs, work);
* :mod:`~pipeline.stage.atomic` -- files written whole or not at all;
* :mod:`~pipeline.stage.state` -- fingerprints: is a stage's output up to date;
* :mod:`~pipeline.stage.inspect_log`, :mod:`~pipeline.stage.figure` -- MCAP inspection logs and PNG figures.
"""
