"""Per-frame terms shared by the features stage and the training environments (mjlab's ``mdp`` idea:
terms as plain functions over batched arrays), and the contract they fill.

* :mod:`~pipeline.terms.layout` -- the observation contract: column names, widths, the history, the clock;
* :mod:`~pipeline.terms.link_motion` -- link positions and velocities from the simulated state;
* :mod:`~pipeline.terms.interaction` -- the DF interaction feature u_t = [phi, grad phi, v_norm, v_tan];
* :mod:`~pipeline.terms.observations` -- root command and proprioception;
* :mod:`~pipeline.terms.fall` -- the fall test of every rollout and environment.
"""
