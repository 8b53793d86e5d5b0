"""The published numbers (the original README, one run each at seed 0): mean and its ±.

Source: the original README and the paper (docs/original.md describes how each was measured). The paper's Table 1 shows
the same values scaled (x10^3; 2-body x10^6; pixel losses x10^5; Table 2, 3-body, x10^2).
"""

# task -> metric -> model -> (mean, ±)
PAPER = {
    "spring": {
        "train_loss": {"baseline": (3.7134e-02, 1.9143e-03), "hnn": (3.6933e-02, 1.9128e-03)},
        "test_loss": {"baseline": (3.6656e-02, 1.8652e-03), "hnn": (3.5928e-02, 1.8328e-03)},
        "energy_mse": {"baseline": (1.7077e-01, 2.06e-02), "hnn": (3.8416e-04, 6.53e-05)},
    },
    "pend": {
        "train_loss": {"baseline": (3.2606e-02, 1.7434e-03), "hnn": (3.2787e-02, 1.7567e-03)},
        "test_loss": {"baseline": (3.5273e-02, 1.7970e-03), "hnn": (3.5586e-02, 1.8178e-03)},
        "energy_mse": {"baseline": (4.1519e-02, 9.62e-03), "hnn": (2.4852e-02, 5.42e-03)},
    },
    "real": {
        "train_loss": {"baseline": (2.7455e-03, 2.0735e-04), "hnn": (9.2376e-03, 5.0263e-04)},
        "test_loss": {"baseline": (2.1864e-03, 3.3296e-04), "hnn": (5.9584e-03, 6.1798e-04)},
        "energy_mse": {"baseline": (3.8564e-01, 6.92e-02), "hnn": (1.4477e-02, 4.65e-03)},
    },
    "2body": {
        "train_loss": {"baseline": (3.2682e-05, 1.2022e-06), "hnn": (2.9959e-06, 6.5500e-08)},
        "test_loss": {"baseline": (2.9575e-05, 8.8900e-07), "hnn": (2.8218e-06, 4.2020e-08)},
        "energy_mse": {"baseline": (6.3276e-02, 3.36e-02), "hnn": (3.8751e-05, 5.04e-06)},
    },
    "3body": {
        "train_loss": {"baseline": (9.5573e-02, 6.5610e-02), "hnn": (8.0346e-02, 2.1470e-02)},
        "test_loss": {"baseline": (3.8000e-01, 4.1612e-01), "hnn": (4.8809e-01, 4.7745e-01)},
        "energy_mse": {"baseline": (1.0906e+02, 7.74e+01), "hnn": (4.1926e-02, 3.39e-02)},
    },
    "pixels": {
        "train_loss": {"baseline": (1.7731e-04, 2.4202e-06), "hnn": (1.8683e-04, 2.4238e-06)},
        "test_loss": {"baseline": (1.7306e-04, 3.2413e-06), "hnn": (1.8451e-04, 3.3422e-06)},
        "energy_mse": {"baseline": (9.2748e-03, 1.14e-03), "hnn": (1.5315e-04, 8.42e-06)},
    },
}
