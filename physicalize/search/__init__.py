"""A search with the QP teacher in the loop, where its rollout of a reference falls (:mod:`physicalize.search.beam`):
windows of the rollout from snapshots of the physics and the controller (:class:`physicalize.rollout.Tracker`), a
small parameter vector per segment that moves what the teacher tracks (:mod:`physicalize.search.guide`), a beam of
elites scored on the segment and a lookahead, and the best re-simulated from the start."""
