"""Batched integration of dx/dt = f(x): one front door, ``rollout``.

Every method integrates the whole batch together, evaluating ``f`` once per stage on a
``(batch, dim)`` tensor, and returns ``(batch, len(t_eval), dim)``. The methods are the
entries of ``hnn.solvers.SOLVERS``, looked up by name: ``rollout`` checks the input and
dispatches, and knows no method by name.
"""
from __future__ import annotations

import warnings

import numpy as np
import torch

from .fixed_step import Field
from .solvers import Solver, get_solver


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


def _check_tolerance(solver: Solver, dtype: torch.dtype, options: dict) -> None:
    """Warn when an adaptive method is asked for a relative accuracy ``dtype`` cannot deliver."""
    rtol = options.get("rtol")
    eps = torch.finfo(dtype).eps
    if solver.adaptive and rtol is not None and rtol < 100 * eps:
        # f is evaluated in dtype: its rounding (~eps relative) caps the accuracy of every stage
        warnings.warn(f"{solver.name}: rtol={rtol:g} is tighter than {dtype} can honour (100 * eps = "
                      f"{100 * eps:.3g}); the error will stall near eps: use rtol >= {100 * eps:.3g} or float64 "
                      "states", stacklevel=3)


def _as_batch(x0) -> torch.Tensor:
    """``x0`` as a finite floating ``(batch, dim)`` tensor (a single ``(dim,)`` state becomes batch 1)."""
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
    return x0


def rollout(f: Field, x0, t_eval, method: str = "solve_ivp", **options) -> torch.Tensor:
    """Integrate ``dx/dt = f(x)`` from every state of ``x0`` and sample at ``t_eval``.

    Args:
        f: maps a ``(batch, dim)`` tensor to ``dx/dt`` of the same shape (a model's
            ``time_derivative`` or a task's true dynamics).
        x0: initial states, ``(batch, dim)`` (a single state ``(dim,)`` is treated as batch 1).
            Its dtype is the dtype ``f`` is evaluated in.
        t_eval: 1-D times (units of the system), starting at the time of ``x0``.
        method: a name in ``hnn.SOLVERS`` (``hnn.register_solver`` adds one); built in:
            ``'solve_ivp'`` (scipy, adaptive; options ``rtol``, ``atol``,
            ``scipy_method='RK45'|'DOP853'|...``), ``'dopri5'`` (the same RK45 in torch with one
            step size per trajectory, each controlled as in its own scipy call; options ``rtol``,
            ``atol``), ``'rk4'`` (fixed step in torch; option ``dt``, default one step per
            ``t_eval`` interval), or the symplectic fixed-step methods of ``hnn.fixed_step``
            (option ``dt`` as for rk4): ``'leapfrog'`` (Stormer-Verlet; exact only for
            separable H = T(p) + V(q), e.g. true dynamics), ``'midpoint'`` (implicit midpoint,
            for any H, the choice for learned models; options ``tol`` (default 1e-12 in float64,
            8 eps in float32) and ``max_iter`` (100) of its fixed-point iteration) and
            ``'yoshida4'`` (order 4; option ``base='leapfrog'|'midpoint'``). All accept
            ``stats={}``, filled with ``nfev``, the number of batched evaluations of ``f`` (and
            for the midpoint ``iterations`` and ``max_step_iterations``), and ``max_norm`` (default
            1e6; None to disable): a state with a component beyond it counts as blown up.
            Fixed-step methods take ``t_eval`` in either direction (backwards for reversibility).

    Returns:
        ``(batch, len(t_eval), dim)``, with ``x0`` at index 0.

    Raises:
        ValueError: for an unknown ``method`` (naming the registered ones) or bad ``x0``, ``t_eval``.
        DivergenceError: when states or derivatives become non-finite or states exceed
            ``max_norm``, naming the trajectories and times (never a silent NaN);
            ``hnn.ConvergenceError`` (a subclass) when the midpoint iteration does not converge.

    Warns (``UserWarning``) when ``rtol`` (adaptive methods: solve_ivp, dopri5) is below 100 eps
    of ``x0``'s dtype or the midpoint ``tol`` below its eps: tolerances the dtype cannot honour.
    """
    solver = get_solver(method)
    x0 = _as_batch(x0)
    _check_tolerance(solver, x0.dtype, options)
    return solver.run(f, x0, _as_t_eval(t_eval), **options)
