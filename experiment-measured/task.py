"""Your own measurements as the package sees them (hnn.TaskSpec): not one of the paper's tasks.

No protocol of the paper applies to a file nobody has seen: ``python analysis/scene_study.py
--data FILE ...`` measures its model kinds (docs/measured.md); reproduce.py leaves it out.
"""
import hnn

TASK = hnn.TaskSpec(
    order=101,
    in_paper=False,
    cost=10,    # rough: 2000 full-batch steps on ~1000 rows, seconds on one core
)
