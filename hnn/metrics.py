"""The paper's metrics, with the paper's error bars.

- ``derivative_mse``: mean of (dx/dt - prediction)^2 over all elements, ± the element-wise
  standard deviation (unbiased) divided by sqrt(number of rows), as the original prints it.
- ``energy_mse``: squared energy error, mean ± ``batch_means_se`` over 5 contiguous groups
  (the original's ``bootstrap_conf``: a batch-means standard error, not a bootstrap).

Per trajectory (the scene cards, the integrator study):

- ``relative_error``: e(t) = |pred - true| / (|pred| + |true|) along rollouts (Finzi et al. 2020).
- ``rollout_error``: the mean over trajectories of the geometric mean of e(t) over t > 0; ``valid_time``:
  the median over trajectories of the time until e(t) first exceeds ``VALID_ERROR``: the two entries of
  ``ROLLOUT_METRICS``, which ``summarize_errors`` (and ``path_errors``, of two sets of paths) reports.
  ``hnn.evaluation.rollout_errors`` rolls a model out by the cards' protocol first.
- ``energy_drift``: max |H(t) - H(0)|, or relative to |H(0)|.
"""
from __future__ import annotations

import statistics

import numpy as np
import torch

VALID_ERROR = 0.1          # a prediction is "valid" while its relative error stays below this


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


def derivative_mse(model, x, dxdt, chunk: int = 65536, field=None) -> tuple[float, float]:
    """The paper's train/test loss of ``model.time_derivative`` (or ``field``) on ``(x, dxdt)``, both ``(rows, dim)``."""
    param = next(model.parameters())
    x = torch.as_tensor(x, dtype=param.dtype, device=param.device)
    dxdt = torch.as_tensor(dxdt, dtype=param.dtype, device=param.device)
    with torch.no_grad():
        field = field or model.time_derivative
        pred = torch.cat([field(x[i:i + chunk]) for i in range(0, len(x), chunk)])
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


def relative_error(pred: torch.Tensor, true: torch.Tensor) -> np.ndarray:
    """e(t) ``(batch, times)`` of two ``(batch, times, dim)`` trajectories; 0 where both are 0."""
    pred, true = pred.to(dtype=torch.float64, device="cpu"), true.to(dtype=torch.float64, device="cpu")
    den = pred.norm(dim=-1) + true.norm(dim=-1)
    err = (pred - true).norm(dim=-1) / torch.where(den > 0, den, torch.ones_like(den))
    return err.numpy()


def geometric_errors(err: np.ndarray) -> np.ndarray:
    """``(batch,)``: the geometric mean over t > 0 of each row of ``err`` ``(batch, times)`` (e(0) = 0
    exactly, so the first time is left out; errors below 1e-16 count as 1e-16)."""
    return np.exp(np.log(np.clip(err[:, 1:], 1e-16, None)).mean(axis=1))


def valid_times(err: np.ndarray, t: np.ndarray) -> list[float]:
    """Each row's time from ``t[0]`` until its error first exceeds ``VALID_ERROR`` (the whole horizon
    ``t[-1] - t[0]`` where it never does)."""
    out = []
    for row in err:
        bad = np.nonzero(row > VALID_ERROR)[0]
        out.append(float(t[bad[0]] - t[0]) if len(bad) else float(t[-1] - t[0]))
    return out


def rollout_error(err: np.ndarray, t: np.ndarray) -> float:
    """The scene cards' rollout error: the mean over trajectories of ``geometric_errors``."""
    return float(geometric_errors(err).mean())


def valid_time(err: np.ndarray, t: np.ndarray) -> float:
    """The scene cards' valid prediction time: the median over trajectories of ``valid_times``."""
    return float(statistics.median(valid_times(err, t)))


# the numbers of a rollout's relative error: name -> metric(err (batch, times), t (times,)) -> a JSON value;
# every study that summarizes rollouts (summarize_errors) reports each one, and a new entry reaches them all
ROLLOUT_METRICS: dict = {"error": rollout_error, "valid_time": valid_time}


def summarize_errors(err: np.ndarray, t: np.ndarray) -> dict:
    """Every ``ROLLOUT_METRICS`` entry of ``err`` ``(batch, times)`` at times ``t`` ``(times,)``, with the
    per-trajectory numbers behind the first two and the horizon: ``{"error", "valid_time",
    "error_per_trajectory", "valid_times", "horizon", ...}``; a trajectory that never leaves ``VALID_ERROR``
    counts the whole horizon (``valid_time == horizon`` means "at least")."""
    out = {"error_per_trajectory": geometric_errors(err).tolist(), "valid_times": valid_times(err, t),
           "horizon": float(t[-1] - t[0])}
    return {**{name: metric(err, t) for name, metric in ROLLOUT_METRICS.items()}, **out}


def path_errors(pred: torch.Tensor, true: torch.Tensor, t) -> dict:
    """``summarize_errors`` of paths ``pred`` against ``true``, both ``(batch, times, dim)`` at times ``t``:
    ``["error"]`` the rollout error, ``["valid_time"]`` the valid prediction time, as the scene cards."""
    t = np.asarray(t.detach().cpu() if torch.is_tensor(t) else t, dtype=np.float64)
    return summarize_errors(relative_error(torch.as_tensor(pred), torch.as_tensor(true)), t)


def energy_drift(H: torch.Tensor, H0: torch.Tensor | None = None, relative: bool = False) -> float:
    """max over trajectories and times of |H(t) - H0|, ``H`` of shape ``(batch, times)``; ``H0``
    ``(batch,)`` defaults to ``H[:, 0]``; ``relative`` divides by |H0| (at least 1e-12)."""
    if H0 is None:
        H0 = H[:, 0]
    if relative:
        return float(((H - H0[:, None]).abs() / H0.abs().clamp_min(1e-12)[:, None]).max())
    return float((H - H0[:, None]).abs().max())
