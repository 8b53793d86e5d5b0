"""Task 2, the ideal pendulum, as reproduce.py and the package see it (hnn.TaskSpec)."""
import math

import hnn

TASK = hnn.TaskSpec(
    order=2,
    protocols={
        "paper": hnn.EnergyProtocol("paper", energy="q2+p2"),
        "corrected": hnn.EnergyProtocol("corrected"),
    },
    # the original README, one run at seed 0: (mean, ±)
    paper={
        "train_loss": {"baseline": (3.2606e-02, 1.7434e-03), "hnn": (3.2787e-02, 1.7567e-03)},
        "test_loss": {"baseline": (3.5273e-02, 1.7970e-03), "hnn": (3.5586e-02, 1.8178e-03)},
        "energy_mse": {"baseline": (4.1519e-02, 9.62e-03), "hnn": (2.4852e-02, 5.42e-03)},
    },
    figures=("energy", "fields", "integration", "energy_bump", "reversibility"),
    # from the original notebooks (docs/original.md); every phase-plane figure starts from x0
    figure_settings={"x0": (2.1, 0.0),
                     "fields": {"lim": 2.6, "gridsize": 10, "t_span": (0.0, 28.0), "num_points": 1000},
                     "integration": {"t_span": (0.0, 20.0), "num_points": 2000}},
    cost=12,    # measured full-settings training time of one model, in seconds on 2 cores (rounded)
    data_cost=0.1,    # seconds of one build of its --quick dataset (0.03 s on a 2-core box at load 5)
    evaluate_cost=5,    # seconds of its --quick evaluation of a row (0.4 s its energy protocols, 4.3 s its 5 figures; 2-core box at load 3)
    # the small-angle period 2 pi / sqrt(6) of H = 3 (1 - cos q) + p^2 (the data swing wider: longer)
    scene_study={"T": 3.0, "dts": (0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.002), "period": 2 * math.pi / math.sqrt(6),
                 "periods": 1000, "unit": "small-angle periods", "grid": True, "drift": True},
    integrator_study={"T": 5.0, "dts": (0.3, 0.1, 0.03, 0.01, 0.003), "batch": 8, "quick": True},
)
