"""A Lennard-Jones cluster, as the package sees it (hnn.TaskSpec): not one of the paper's tasks, so no protocol
of the paper's tables. Its one energy protocol is named ``corrected`` as the paper's tasks' protocols that
measure the true H at a tight tolerance are: 15 clusters (``initial_state(0..14)``, every pair, no cutoff)
over the data's span. Its scene card: ``python analysis/scene_study.py --scenes gravity lattice lj``
(docs/bodies.md)."""
import hnn

TASK = hnn.TaskSpec(
    order=21,
    protocols={"corrected": hnn.EnergyProtocol("corrected", x0="seeds", t_span=(0.0, 5.0), num_points=200,
                                               rtol=1e-10, atol=1e-10)},    # the data's tolerances,
    in_paper=False,
    cost=20,    # a rough full-settings training time of one Adam model, seconds on 2 cores
    # T: the data's span; no long drift run (the cluster has no period)
    scene_study={"T": 5.0, "dts": (0.1, 0.05, 0.02, 0.01, 0.005), "page": "bodies"},
)
