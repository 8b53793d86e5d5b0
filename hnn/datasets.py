"""From a system's true dynamics to a dataset: sample, integrate in one batch, add noise, split.

The recipe of the paper's one-degree-of-freedom tasks (spring, pendulum): start states on a
ring of random phase-space radius, trajectories on a fixed time grid, Gaussian noise on the
inputs only (the targets stay the clean derivatives), the first half of the trajectories for
training. Draws come from ``numpy.random.RandomState(seed)`` in the original's order, so a
seed gives the original's dataset.
"""
from __future__ import annotations

import numpy as np
import torch

from .integrators.integrate import rollout


def sample_ring(rng: np.random.RandomState, num_trajectories: int, radius_range: tuple[float, float],
                num_points: int, noise_std: float) -> tuple[np.ndarray, np.ndarray]:
    """Start states ``(num, 2)`` with radius ~ U[radius_range], and their noise ``(num, num_points, 2)``.

    Per trajectory, in this order: a direction from U[-1, 1]^2, a radius, N(0, noise_std^2)
    noise for q at every point, then for p (the original's draw order).
    """
    lo, hi = radius_range
    x0 = np.empty((num_trajectories, 2))
    noise = np.empty((num_trajectories, num_points, 2))
    for i in range(num_trajectories):
        direction = rng.rand(2) * 2 - 1
        radius = rng.rand() * (hi - lo) + lo
        x0[i] = direction / np.sqrt((direction ** 2).sum()) * radius
        noise[i, :, 0] = rng.randn(num_points) * noise_std
        noise[i, :, 1] = rng.randn(num_points) * noise_std
    return x0, noise


def trajectory_dataset(dynamics, x0: np.ndarray, t_eval: np.ndarray, noise: np.ndarray,
                       test_split: float = 0.5, rtol: float = 1e-10) -> dict:
    """Integrate every start state at once and build the training arrays.

    Args:
        dynamics: the true ``dx/dt = f(x)`` on ``(batch, dim)`` tensors.
        x0: ``(num, dim)`` start states; ``t_eval``: ``(T,)`` times; ``noise``: ``(num, T, dim)``
            added to the inputs only.
        test_split: fraction of rows (trailing trajectories) held out.

    Returns:
        ``x``, ``dxdt``, ``test_x``, ``test_dxdt`` as float32 ``(rows, dim)`` arrays (rows =
        trajectories x T, trajectory-major), ``dt`` (the grid step) and ``t_eval``.
    """
    x0 = torch.as_tensor(x0, dtype=torch.float64, device="cpu")      # datasets are made on the CPU
    # atol 1e-6: solve_ivp's default, which the original kept (the published datasets)
    clean = rollout(dynamics, x0, t_eval, rtol=rtol, atol=1e-6, threads=None)      # (num, T, dim)
    dxdt = dynamics(clean.reshape(-1, clean.shape[-1])).numpy()
    x = clean.reshape(-1, clean.shape[-1]).numpy() + noise.reshape(-1, noise.shape[-1])
    split = int(len(x) * (1 - test_split))
    as32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    return {"x": as32(x[:split]), "dxdt": as32(dxdt[:split]),
            "test_x": as32(x[split:]), "test_dxdt": as32(dxdt[split:]),
            "dt": float(t_eval[1] - t_eval[0]), "t_eval": np.asarray(t_eval)}


def ring_dataset(dynamics, seed: int, samples: int, t_span: tuple[float, float], timescale: int,
                 radius_range: tuple[float, float], noise_std: float, test_split: float = 0.5) -> dict:
    """The spring/pendulum recipe: ``samples`` trajectories of ``timescale`` points per time unit
    over ``t_span``, started on rings of radius ~ U[radius_range], seeded by ``seed``."""
    t_eval = np.linspace(t_span[0], t_span[1], int(timescale * (t_span[1] - t_span[0])))
    x0, noise = sample_ring(np.random.RandomState(seed), samples, radius_range, len(t_eval), noise_std)
    return trajectory_dataset(dynamics, x0, t_eval, noise, test_split)


def paths_dataset(dynamics, x0: torch.Tensor, t_eval: np.ndarray, test_split: float, rtol: float, atol: float,
                  method: str = "dop853") -> dict:
    """The many-body scenes' recipe: every start state ``x0`` ``(num, dim)`` integrated at once by ``method``
    on ``t_eval`` ``(T,)``, no noise; the first ``test_split`` of the paths test, the rest train (the orbit
    tasks' split). Float32 ``x``, ``dxdt`` (``dynamics`` at each row), ``test_x``, ``test_dxdt`` ``(rows, dim)``
    (trajectory-major), the grid step ``dt`` and ``t_eval``."""
    paths = rollout(dynamics, x0, t_eval, method=method, rtol=rtol, atol=atol)
    x = paths.reshape(-1, paths.shape[-1])
    dxdt = dynamics(x)
    split = int(len(x0) * test_split) * len(t_eval)
    as32 = lambda a: np.ascontiguousarray(a.numpy(), dtype=np.float32)  # noqa: E731
    return {"x": as32(x[split:]), "dxdt": as32(dxdt[split:]), "test_x": as32(x[:split]),
            "test_dxdt": as32(dxdt[:split]), "dt": float(t_eval[1] - t_eval[0]), "t_eval": t_eval}
