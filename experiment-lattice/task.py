"""A chain of springs, as the package sees it (hnn.TaskSpec): not one of the paper's tasks, so no energy protocol
of the paper's tables; its energy and rollout errors against the chain's length are the bodies study's
(``analysis/bodies.py``, docs/bodies.md)."""
import hnn

TASK = hnn.TaskSpec(
    order=20,
    in_paper=False,
    cost=20,    # a rough full-settings training time of one Adam model, seconds on 2 cores
)
