"""Task 4, two bodies under gravity, as reproduce.py and the package see it (hnn.TaskSpec)."""
import hnn

TASK = hnn.TaskSpec(
    order=4,
    # the paper's n-body protocols already use the physical energy; nothing to correct
    protocols={"paper": hnn.EnergyProtocol("paper", x0="seeds", t_span=(0.0, 25.0), num_points=500, rtol=1e-9)},
    # the original README, one run at seed 0: (mean, ±)
    paper={
        "train_loss": {"baseline": (3.2682e-05, 1.2022e-06), "hnn": (2.9959e-06, 6.5500e-08)},
        "test_loss": {"baseline": (2.9575e-05, 8.8900e-07), "hnn": (2.8218e-06, 4.2020e-08)},
        "energy_mse": {"baseline": (6.3276e-02, 3.36e-02), "hnn": (3.8751e-05, 5.04e-06)},
    },
    figures=("energy", "orbits"),
    cost=25,    # measured full-settings training time of its HNN, seconds on one thread (26.8 s, docs/speed.md full run)
    data_cost=0.3,    # seconds of one build of its --quick dataset (1000 orbits: 0.2 s on a 2-core box at load 2, 1.1 s at 5)
    evaluate_cost=3.5,    # seconds of its --quick evaluation of a row (0.1 s its energy protocols, 3.1 s its 2 figures (the orbits 2.6); 2-core box at load 3)
    scene_study={"T": 20.0, "dts": (0.5, 0.2, 0.1, 0.05, 0.02, 0.01), "period": None, "periods": 100,
                 "unit": "orbits", "grid": True, "drift": True},
    integrator_study={"T": 3.0, "dts": (0.2, 0.1, 0.03, 0.01, 0.002), "batch": 8, "quick": True},
)
