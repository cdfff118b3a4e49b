"""Per-frame terms shared by the features stage and the training environments (mjlab's ``mdp`` idea:
terms as plain functions over batched arrays).

* :mod:`~pipeline.terms.link_motion` -- link positions and velocities from the simulated state;
* :mod:`~pipeline.terms.interaction` -- the DF interaction feature u_t = [phi, grad phi, v_norm, v_tan];
* :mod:`~pipeline.terms.observations` -- root command and proprioception.
"""
