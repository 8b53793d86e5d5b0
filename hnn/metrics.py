"""The paper's metrics, with the paper's error bars.

- ``derivative_loss``: mean of (dx/dt - prediction)^2 over all elements, ± the element-wise
  standard deviation (unbiased) divided by sqrt(number of rows), as the original prints it.
- ``energy_mse``: squared energy error, mean ± ``batch_means_se`` over 5 contiguous groups
  (the original's ``bootstrap_conf``: a batch-means standard error, not a bootstrap).
"""
from __future__ import annotations

import numpy as np
import torch


def _to_numpy(a) -> np.ndarray:
    return a.detach().cpu().numpy() if torch.is_tensor(a) else np.asarray(a)


def mean_and_se(values) -> tuple[float, float]:
    """``(mean, std / sqrt(rows))`` of a ``(rows, dims)`` array, mean and std over all elements.

    std is unbiased (ddof=1); the denominator counts rows, not elements, as the original does.
    """
    v = _to_numpy(values).astype(np.float64)
    if v.ndim == 1:
        v = v[:, None]
    rows = v.shape[0]
    std = v.std(ddof=1) if v.size > 1 else 0.0
    return float(v.mean()), float(std / np.sqrt(rows))


def derivative_loss(model, x, dxdt, chunk: int = 65536) -> tuple[float, float]:
    """The paper's train/test loss of ``model.time_derivative`` on ``(x, dxdt)``, both ``(rows, dim)``."""
    param = next(model.parameters())
    x = torch.as_tensor(x, dtype=param.dtype, device=param.device)
    dxdt = torch.as_tensor(dxdt, dtype=param.dtype, device=param.device)
    with torch.no_grad():
        pred = torch.cat([model.time_derivative(x[i:i + chunk]) for i in range(0, len(x), chunk)])
    return mean_and_se((dxdt - pred) ** 2)


def batch_means_se(values, splits: int = 5) -> float:
    """Standard error from ``splits`` contiguous groups: std (ddof=0) of the group means / sqrt(splits)."""
    v = _to_numpy(values).astype(np.float64)
    if len(v) % splits:
        raise ValueError(f"batch_means_se needs a length divisible by splits={splits}, got {len(v)}")
    means = v.reshape(splits, -1, *v.shape[1:]).reshape(splits, -1).mean(axis=1)
    return float(means.std() / np.sqrt(splits))


def energy_mse(energy_true, energy_pred, splits: int = 5) -> tuple[float, float]:
    """Squared energy error: ``(mean, batch-means standard error)``.

    Shapes ``(trials, time)`` (groups of whole trials, as for spring, pend, 2-body, 3-body) or
    ``(time,)`` (contiguous chunks of one trajectory, as for the real and pixel pendulums).
    """
    e_true, e_pred = _to_numpy(energy_true), _to_numpy(energy_pred)
    if e_true.shape != e_pred.shape:
        raise ValueError(f"energy arrays differ in shape: {e_true.shape} vs {e_pred.shape}")
    dist = (e_true.astype(np.float64) - e_pred.astype(np.float64)) ** 2
    return float(dist.mean()), batch_means_se(dist, splits)
