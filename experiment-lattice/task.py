"""A chain of springs, as the package sees it (hnn.TaskSpec): not one of the paper's tasks, so no protocol of the
paper's tables. Its one energy protocol is named ``corrected`` as the paper's tasks' protocols that measure the
true H at a tight tolerance are: 15 chains (``initial_state(0..14)``) over the data's span. Its energy and
rollout errors against the chain's length are the bodies study's (``analysis/bodies.py``); its scene card is
the scene study's (``python analysis/scene_study.py --scenes gravity lattice lj``), both in docs/bodies.md."""
import hnn

TASK = hnn.TaskSpec(
    order=20,
    protocols={"corrected": hnn.EnergyProtocol("corrected", x0="seeds", t_span=(0.0, 10.0), num_points=200,
                                               rtol=1e-10, atol=1e-10)},    # the data's tolerances,
    in_paper=False,
    cost=20,    # a rough full-settings training time of one Adam model, seconds on 2 cores
    # T: the data's span; no long drift run (the chain's modes have many periods, none the scene's)
    scene_study={"T": 10.0, "dts": (0.5, 0.2, 0.1, 0.05, 0.02), "page": "bodies"},
)
