"""Task 1, the ideal mass-spring, as reproduce.py and the package see it (hnn.TaskSpec)."""
import math

import hnn

TASK = hnn.TaskSpec(
    order=1,
    protocols={
        # the notebook's t_span [0, 20] is scaled in place to [0, 21.8] before the metric cell
        "paper": hnn.EnergyProtocol("paper", t_span=(0.0, 21.8), energy="q2+p2", time_rescale=1.09),
        "corrected": hnn.EnergyProtocol("corrected"),
    },
    # the original README, one run at seed 0: (mean, ±)
    paper={
        "train_loss": {"baseline": (3.7134e-02, 1.9143e-03), "hnn": (3.6933e-02, 1.9128e-03)},
        "test_loss": {"baseline": (3.6656e-02, 1.8652e-03), "hnn": (3.5928e-02, 1.8328e-03)},
        "energy_mse": {"baseline": (1.7077e-01, 2.06e-02), "hnn": (3.8416e-04, 6.53e-05)},
    },
    figures=("energy", "fields", "integration", "energy_bump", "reversibility"),
    # from the original notebooks (docs/original.md); every phase-plane figure starts from x0
    figure_settings={"x0": (1.0, 0.0),
                     "fields": {"lim": 1.2, "gridsize": 10, "t_span": (0.0, 30.0), "num_points": 2000},
                     "integration": {"t_span": (0.0, 20.0), "num_points": 2000}},
    cost=12,    # measured full-settings training time of one model, in seconds on 2 cores (rounded)
    data_cost=0.1,    # seconds of one build of its --quick dataset (0.03 s on a 2-core box at load 5)
    evaluate_cost=5,    # seconds of its --quick evaluation of a row (0.4 s its energy protocols, 4.4 s its 5 figures; 2-core box at load 3)
    scene_study={"T": 3.0, "dts": (0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.002), "period": math.pi,
                 "periods": 1000, "unit": "periods", "grid": True, "drift": True},
    integrator_study={"T": 5.0, "dts": (0.3, 0.1, 0.03, 0.01, 0.003), "batch": 8, "quick": True},
)
