"""What the CPU and mjlab backends share, as plain functions over numpy or torch arrays (mjlab's ``mdp`` idea):
the tasks and their success rules (:mod:`train.mdp.tasks`), the reward table's terms and weights
(:mod:`train.mdp.rewards`), the six randomisations (:mod:`train.mdp.randomize`). The observation terms are
:mod:`pipeline.terms` (the features stage writes the same values) and the termination is the fall test of
:mod:`pipeline.terms.fall`: both are shared beyond training. Each backend binds these to its own state in
``train/envs/<backend>/``."""
