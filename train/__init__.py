"""Training (paper Sec. III-B and III-C), laid out as mjlab lays out a task:

* the algorithms, each one file read top to bottom: :mod:`train.bc` (behaviour cloning), :mod:`train.dagger`
  (DAgger from the QP teacher), :mod:`train.aip` (PPO with the AIP and AMP priors); :mod:`train.run` chains the
  VAE, BC and DAgger of ``lessmimic train-bc``;
* the models beside them: :mod:`train.vae`, :mod:`train.policy`, :mod:`train.rl_model` (the policy as an rsl_rl
  actor), :mod:`train.discriminator`, :mod:`train.normalize`;
* who acts: :mod:`train.actors` (the student, the teacher), :mod:`train.teacher` (the physicalize stage's QP
  controller as a service: the only module here that imports :mod:`physicalize`);
* :mod:`train.mdp`: what both backends share (tasks and their success rules, rewards, randomisations);
* :mod:`train.envs`: the two backends, ``cpu`` (native MuJoCo) and ``mjlab`` (MuJoCo Warp on a GPU);
* :mod:`train.evaluation`: Table 2 (:mod:`train.evaluation.table2`) and Table 3's chains;
* :mod:`train.episodes` (a corpus's episodes) and :mod:`train.ablation` (Table 2's ablation switch).

The observation contract (columns, widths, the history, the clock) is :mod:`pipeline.terms.layout`'s; the
observation terms themselves are :mod:`pipeline.terms`' (the features stage computes the same), and the fall test
is :mod:`pipeline.terms.fall`.
"""
