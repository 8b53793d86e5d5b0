"""Task 1, the ideal mass-spring: H(q, p) = q^2 + p^2 (k = 2, m = 1/2 in the paper's units).

Dynamics dq/dt = 2p, dp/dt = -2q: angular frequency 2, period pi. The paper writes
H = kq^2/2 + p^2/(2m) with k = m = 1; the published numbers come from the code's H, kept here.
"""
import torch

from hnn.datasets import ring_dataset

RADIUS_RANGE = (0.1, 1.0)   # phase-space radius of the start states (the paper calls it an energy range)
T_SPAN = (0.0, 3.0)
TIMESCALE = 10              # points per time unit: 30 points on [0, 3]
NOISE_STD = 0.1


def hamiltonian(x):
    """H of states ``x = [q, p]``, a tensor of shape ``(batch, 2)``; returns ``(batch,)``."""
    q, p = x[..., 0], x[..., 1]
    return q ** 2 + p ** 2


def dynamics(x: torch.Tensor) -> torch.Tensor:
    """Hamilton's equations, ``(batch, 2) -> (batch, 2)``: (dH/dp, -dH/dq) = (2p, -2q)."""
    q, p = x[..., 0], x[..., 1]
    return torch.stack([2 * p, -2 * q], dim=-1)


def get_dataset(seed: int = 0, samples: int = 50, test_split: float = 0.5, noise_std: float = NOISE_STD) -> dict:
    """``samples`` noisy trajectories of 30 points on [0, 3]; the first half train, the rest test.

    Returns float32 ``x``, ``dxdt``, ``test_x``, ``test_dxdt``, each (750, 2) by default, plus
    the grid step ``dt`` and ``t_eval``.
    """
    return ring_dataset(dynamics, seed, samples, T_SPAN, TIMESCALE, RADIUS_RANGE, noise_std, test_split)
