"""The human stage: mocap (or the embedded synthetic default, or a synthetic corpus) -> validated human clips in
``datasets/<NAME>/human/``. It runs before retargeting; no other stage imports it."""
