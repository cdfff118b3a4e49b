"""The stages chained as the commands run them: ``lessmimic retarget`` is the human stage (:mod:`ingest`) feeding the
retarget stage (:mod:`retarget.stage`), which never imports it."""

from __future__ import annotations


def retarget(
    input_path: str | None,
    name: str,
    *,
    overwrite: bool = False,
    jobs: int = 1,
    executor: str = "local",
    body_model: str | None = None,
    height_override: float | None = None,
    variants=(),
    read: dict | None = None,
) -> dict:
    """Ingest ``input_path`` (a file, a folder, ``synthetic:<seeds>``, or None: the embedded default) into
    ``datasets/<name>/human/`` and retarget its clips into ``datasets/<name>/retargeted/``; the human stage runs only
    when the retargeted dataset is not up to date (:func:`retarget.stage.run_stage`); ``variants``: the geometry
    augmentation's (:func:`retarget.augment.parse_variants`); ``read``: the readers' options given (``fps``, ``units``,
    ``mesh``: :func:`ingest.stage.load_input`), part of what the output depends on."""
    from ingest.stage import ingest, input_label, source_fingerprint
    from pipeline.stage.state import files_fingerprint, fingerprint
    from retarget.stage import run_stage

    read = {k: v for k, v in (read or {}).items() if v is not None}
    source = source_fingerprint(input_path)
    if read:  # read otherwise, the same files are another input
        mesh = {"mesh": files_fingerprint([read["mesh"]])} if "mesh" in read else {}
        source += " read with " + fingerprint(**{**read, **mesh})

    def human():
        return ingest(input_path, name, overwrite=True, body_model=body_model, read=read).clips

    return run_stage(
        name,
        source,
        human,
        input_label=input_label(input_path),
        overwrite=overwrite,
        jobs=jobs,
        executor=executor,
        body_model=body_model,
        height_override=height_override,
        variants=variants,
    )
