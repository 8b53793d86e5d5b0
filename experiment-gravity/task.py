"""Gravity of N bodies, softened, as the package sees it (hnn.TaskSpec): not one of the paper's tasks, so no
protocol of the paper's tables. Its one energy protocol is named ``corrected`` as the paper's tasks' protocols
that measure the true H at a tight tolerance are: 15 disks (``initial_state(0..14)``) over the data's span,
the true H of each learned path against the true path's. The scene study's card for it and the other scenes of
many bodies: ``python analysis/scene_study.py --scenes gravity lattice lj`` (docs/bodies.md)."""
import hnn

TASK = hnn.TaskSpec(
    order=22,
    protocols={"corrected": hnn.EnergyProtocol("corrected", x0="seeds", t_span=(0.0, 2.0), num_points=200,
                                               rtol=1e-10, atol=1e-10)},    # the data's tolerances,
    in_paper=False,
    cost=20,    # a rough full-settings training time of one Adam model, seconds on 2 cores
    # T: the data's span (the disk turns about a third of a turn); no long drift run (the disk has no period)
    scene_study={"T": 2.0, "dts": (0.1, 0.05, 0.02, 0.01, 0.005), "page": "bodies"},
)
