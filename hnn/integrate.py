"""Batched integration of dx/dt = f(x): one front door, ``rollout``.

Every method integrates the whole batch together, evaluating ``f`` once per stage on a
``(batch, dim)`` tensor, and returns ``(batch, len(t_eval), dim)``.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
import torch
from scipy.integrate import solve_ivp

Field = Callable[[torch.Tensor], torch.Tensor]


class DivergenceError(FloatingPointError):
    """A rollout produced non-finite states. ``trajectories`` and ``times`` say which and when."""

    def __init__(self, message: str, trajectories=(), times=()):
        super().__init__(message)
        self.trajectories = list(trajectories)
        self.times = list(times)


def _as_t_eval(t_eval) -> np.ndarray:
    t = np.asarray(t_eval.detach().cpu() if torch.is_tensor(t_eval) else t_eval, dtype=np.float64)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError(f"t_eval must be a 1-D grid of at least 2 times, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("t_eval contains NaN or inf")
    steps = np.diff(t)
    if not (np.all(steps > 0) or np.all(steps < 0)):
        raise ValueError("t_eval must be strictly increasing (or strictly decreasing to integrate backwards)")
    return t


def _divergence(message: str, bad_rows, times) -> DivergenceError:
    rows = [int(i) for i in bad_rows]
    shown = ", ".join(f"#{i} at t={t:.4g}" for i, t in zip(rows[:10], times[:10]))
    more = f" (+{len(rows) - 10} more)" if len(rows) > 10 else ""
    return DivergenceError(
        f"{message}: {len(rows)} trajectories diverged: {shown}{more}. Reduce the step size or tolerance, "
        "or check that the initial states lie where the model was trained.", rows, list(times))


def _solve_ivp(f: Field, x0: torch.Tensor, t: np.ndarray, rtol: float = 1e-3, atol: float = 1e-6,
               scipy_method: str = "RK45", max_norm: float | None = 1e6, stats: dict | None = None) -> torch.Tensor:
    """scipy's adaptive solver on the flattened batch: one call, one batched ``f`` per stage."""
    batch, dim = x0.shape
    dtype, device = x0.dtype, x0.device
    nfev = 0

    def fun(time, y):
        nonlocal nfev
        nfev += 1
        if max_norm is not None and not np.abs(y).max() <= max_norm:
            rows = np.nonzero(~(np.abs(y.reshape(batch, dim)) <= max_norm).all(axis=1))[0].tolist()
            raise _divergence(f"solve_ivp: states beyond max_norm={max_norm:g}", rows, [float(time)] * len(rows))
        x = torch.from_numpy(y.reshape(batch, dim))
        if x.dtype != dtype or x.device != device:
            x = x.to(dtype=dtype, device=device)
        dxdt = f(x).detach()
        if dxdt.shape != x.shape:
            raise ValueError(f"f must map (batch, dim) = {tuple(x.shape)} to the same shape, got {tuple(dxdt.shape)}")
        out = dxdt.cpu().numpy().reshape(-1)
        if not np.isfinite(out).all():
            rows = np.nonzero(~np.isfinite(out.reshape(batch, dim)).all(axis=1))[0].tolist()
            raise _divergence("solve_ivp: non-finite dx/dt", rows, [float(time)] * len(rows))
        return out

    y0 = x0.detach().cpu().numpy().astype(np.float64).reshape(-1)
    with torch.no_grad():
        sol = solve_ivp(fun, (t[0], t[-1]), y0, method=scipy_method, t_eval=t, rtol=rtol, atol=atol)
    if stats is not None:
        stats["nfev"] = nfev
    if not sol.success:
        raise DivergenceError(f"solve_ivp ({scipy_method}, rtol={rtol}, atol={atol}) failed at "
                              f"t={sol.t[-1] if len(sol.t) else t[0]:.4g}: {sol.message}")
    y = sol.y.reshape(batch, dim, len(t)).transpose(0, 2, 1)
    return torch.from_numpy(np.ascontiguousarray(y)).to(dtype=dtype, device=device)


def rk4_step(f: Field, x: torch.Tensor, dt) -> torch.Tensor:
    """The classic RK4 increment ``x(t + dt) - x(t)`` of dx/dt = f(x); ``dt`` a float or ``(batch, 1)``."""
    k1 = f(x)
    k2 = f(x + dt / 2 * k1)
    k3 = f(x + dt / 2 * k2)
    k4 = f(x + dt * k3)
    return dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _rk4(f: Field, x0: torch.Tensor, t: np.ndarray, dt: float | None = None, max_norm: float | None = 1e6,
         stats: dict | None = None) -> torch.Tensor:
    """Fixed-step RK4; each interval of ``t_eval`` is cut into equal steps no longer than ``|dt|``.

    Runs in the caller's grad mode, so a rollout can be differentiated when wanted. Rows are
    independent, so a row that blows up is recorded (first time it is non-finite or beyond
    ``max_norm``) and the others finish; then the error names them all.
    """
    if dt is not None and not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"rk4 needs a positive finite dt, got {dt!r}")
    out = [x0]
    x = x0
    nfev = 0
    first_bad = torch.full((len(x0),), float("nan"), dtype=torch.float64)
    for k in range(len(t) - 1):
        span = t[k + 1] - t[k]
        n = 1 if dt is None else max(1, math.ceil(abs(span) / dt - 1e-9))
        h = span / n
        for _ in range(n):
            x = x + rk4_step(f, x, h)
            nfev += 4
        bad = ~torch.isfinite(x).all(dim=1)
        if max_norm is not None:
            bad |= ~(x.detach().abs() <= max_norm).all(dim=1)
        new = bad & torch.isnan(first_bad)
        if new.any():
            first_bad[new] = float(t[k + 1])
            x = torch.where(bad[:, None], torch.zeros_like(x), x)   # keep the dead rows from overflowing
        out.append(x)
    if stats is not None:
        stats["nfev"] = nfev
    diverged = torch.nonzero(~torch.isnan(first_bad)).flatten().tolist()
    if diverged:
        raise _divergence(f"rk4 (dt={dt}, max_norm={max_norm})", diverged, first_bad[diverged].tolist())
    return torch.stack(out, dim=1)


_METHODS = {"solve_ivp": _solve_ivp, "rk4": _rk4}


def rollout(f: Field, x0, t_eval, method: str = "solve_ivp", **options) -> torch.Tensor:
    """Integrate ``dx/dt = f(x)`` from every state of ``x0`` and sample at ``t_eval``.

    Args:
        f: maps a ``(batch, dim)`` tensor to ``dx/dt`` of the same shape (a model's
            ``time_derivative`` or a task's true dynamics).
        x0: initial states, ``(batch, dim)`` (a single state ``(dim,)`` is treated as batch 1).
            Its dtype is the dtype ``f`` is evaluated in.
        t_eval: 1-D times (units of the system), starting at the time of ``x0``.
        method: ``'solve_ivp'`` (scipy, adaptive; options ``rtol``, ``atol``,
            ``scipy_method='RK45'|'DOP853'|...``) or ``'rk4'`` (fixed step in torch; option ``dt``,
            default one step per ``t_eval`` interval). Both accept ``stats={}``, filled with
            ``nfev``, the number of batched evaluations of ``f``, and ``max_norm`` (default
            1e6; None to disable): a state with a component beyond it counts as blown up.

    Returns:
        ``(batch, len(t_eval), dim)``, with ``x0`` at index 0.

    Raises:
        DivergenceError: when states or derivatives become non-finite or states exceed
            ``max_norm``, naming the trajectories and times (never a silent NaN).
    """
    if method not in _METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {sorted(_METHODS)}")
    x0 = torch.as_tensor(x0)
    if x0.dim() == 1:
        x0 = x0[None]
    if x0.dim() != 2:
        raise ValueError(f"x0 must have shape (batch, dim), got {tuple(x0.shape)}")
    if not x0.is_floating_point():
        x0 = x0.to(torch.get_default_dtype())
    if not torch.isfinite(x0).all():
        rows = torch.nonzero(~torch.isfinite(x0).all(dim=1)).flatten().tolist()
        raise ValueError(f"x0 has non-finite values in rows {rows[:10]}")
    return _METHODS[method](f, x0, _as_t_eval(t_eval), **options)
