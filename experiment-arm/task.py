"""The two-link arm as the package sees it (hnn.TaskSpec): not one of the paper's six tasks.

Measured by analysis/arm.py (field and rollout errors of the model kinds at one budget), not by the
paper's energy MSE; reproduce.py leaves it out.
"""
import hnn

TASK = hnn.TaskSpec(
    order=110,
    in_paper=False,
    cost=30,    # rough: 3000 full-batch steps of a 200-unit mechanical model on 2000 states, seconds on one core
)
