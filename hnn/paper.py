"""The published numbers (the original README, one run each at seed 0): mean and its ±, per task.

Each task declares its own in its ``task.py`` (``TaskSpec.paper``); ``PAPER`` is the read-only
view of all of them, read from the task folders when used:

    PAPER[task][metric][model] -> (mean, ±)     # metric: train_loss, test_loss, energy_mse; model: baseline, hnn

Source: the original README and the paper (docs/original.md describes how each was measured). The paper's Table 1 shows
the same values scaled (x10^3; 2-body x10^6; pixel losses x10^5; Table 2, 3-body, x10^2).
"""
from .tasks import PAPER

__all__ = ["PAPER"]
