"""Gravity of N bodies, softened, as the package sees it (hnn.TaskSpec): not one of the paper's tasks, so no
energy protocol of the paper's tables."""
import hnn

TASK = hnn.TaskSpec(
    order=22,
    in_paper=False,
    cost=20,    # a rough full-settings training time of one Adam model, seconds on 2 cores
)
