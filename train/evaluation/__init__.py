"""The paper's evaluation protocol: Table 2's cells (:mod:`train.evaluation.table2`) and Table 3's long-horizon
chains (:mod:`train.evaluation.chains`), one harness for the student policy and the QP teacher. A task's success
rule is :mod:`train.mdp.tasks`' (the environments measure it every step)."""
