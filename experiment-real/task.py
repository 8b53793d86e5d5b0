"""Task 3, the real pendulum, as reproduce.py and the package see it (hnn.TaskSpec).

It has no known true field: its figures show the measurements, and the energy bump and
reversibility start from the first measured test state.
"""
import hnn

TASK = hnn.TaskSpec(
    order=3,
    protocols={
        # the notebook passed no tolerance: solve_ivp's rtol 1e-3, loose enough to add error
        "paper": hnn.EnergyProtocol("paper", x0="test_segment", rtol=1e-3),
        "corrected": hnn.EnergyProtocol("corrected", x0="test_segment", rtol=1e-9, atol=1e-9),
    },
    # the original README, one run at seed 0: (mean, ±)
    paper={
        "train_loss": {"baseline": (2.7455e-03, 2.0735e-04), "hnn": (9.2376e-03, 5.0263e-04)},
        "test_loss": {"baseline": (2.1864e-03, 3.3296e-04), "hnn": (5.9584e-03, 6.1798e-04)},
        "energy_mse": {"baseline": (3.8564e-01, 6.92e-02), "hnn": (1.4477e-02, 4.65e-03)},
    },
    figures=("energy", "real_fields", "energy_bump", "reversibility"),
    cost=8,     # measured full-settings training time of one model, in seconds on 2 cores (rounded)
    data_cost=0.1,    # seconds of one build of its --quick dataset (0.02 s on a 2-core box at load 5)
    evaluate_cost=3,    # seconds of its --quick evaluation of a row (0.2 s its energy protocols, 2.5 s its 4 figures; 2-core box at load 3)
    scene_study={},
)
