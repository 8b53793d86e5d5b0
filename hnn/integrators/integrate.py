"""Batched integration of dx/dt = f(x): one front door, ``rollout``.

Every method integrates the whole batch together, evaluating ``f`` once per stage on a
``(batch, dim)`` tensor, and returns ``(batch, len(t_eval), dim)``. The methods are the
entries of ``hnn.integrators.solvers.SOLVERS``, looked up by name: ``rollout`` checks the input and
dispatches, and knows no method by name.
"""
from __future__ import annotations

import inspect
import warnings

import numpy as np
import torch

from .fixed_step import Field
from ..interface import EnergyField, Model, step_map_of
from .map_steps import check_request, map_rollout
from ..modes import frozen_weights, in_model_axis
from .adaptive import default_tolerances
from .solvers import Solver, get_solver
from .stability import warn_if_unstable
from ..threads import torch_threads


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


def field_device(f) -> torch.device | None:
    """The device of the weights behind ``f`` (an ``nn.Module``, a bound method of one, such as
    ``model.time_derivative``, or a model's ``field``), or None for a plain function (true dynamics),
    which runs anywhere."""
    if isinstance(f, EnergyField):
        f = f.whole
    owner = f if isinstance(f, torch.nn.Module) else getattr(f, "__self__", None)
    if not isinstance(owner, torch.nn.Module):
        return None
    for tensor in owner.parameters():
        return tensor.device
    for tensor in owner.buffers():
        return tensor.device
    return None


def _as_batch(x0, device: torch.device | None) -> torch.Tensor:
    """``x0`` as a finite floating ``(batch, dim)`` tensor (a single ``(dim,)`` state becomes batch 1):
    a tensor where it lies, an array on ``device`` (the field's; the CPU for a plain function); a
    tensor on another device than the field's weights is a ValueError naming both."""
    if torch.is_tensor(x0):
        if device is not None and x0.device != device:
            raise ValueError(f"x0 is on {x0.device} but the model's weights are on {device}: move one to the "
                             f"other, e.g. x0.to('{device}') or model.to('{x0.device}')")
    else:
        x0 = torch.as_tensor(np.asarray(x0), device=device or "cpu")
    if x0.dim() == 1:
        x0 = x0[None]
    if x0.dim() != 2:
        raise ValueError(f"x0 must have shape (batch, dim), got {tuple(x0.shape)}")
    if not x0.is_floating_point():
        x0 = x0.to(torch.get_default_dtype())
    if not in_model_axis() and not torch.isfinite(x0).all():
        rows = torch.nonzero(~torch.isfinite(x0).all(dim=1)).flatten().tolist()
        raise ValueError(f"x0 has non-finite values in rows {rows[:10]}")
    return x0


# With threads=None, rollouts of at most this many states still run on one torch thread: their products are
# too small to split, and two processes each spinning two threads on two cores slow each other many times over.
SMALL_BATCH_ROWS = 64


def rollout(f: Field, x0, t_eval, method: str = "solve_ivp", differentiable: bool = False,
            threads: int | None = 1, rtol: float | None = None, atol: float | None = None,
            **options) -> torch.Tensor:
    """Integrate ``dx/dt = f(x)`` from every state of ``x0`` and sample at ``t_eval``.

    Args:
        f: maps a ``(batch, dim)`` tensor to ``dx/dt`` of the same shape (a task's true dynamics), or
            an ``hnn.Model``, whose declared ``field`` is stepped (a separable model's halves one at a
            time where a stage reads one); a model's bound ``time_derivative`` is taken as the model.
        x0: initial states, ``(batch, dim)`` (a single state ``(dim,)`` is treated as batch 1).
            Its dtype is the dtype ``f`` is evaluated in.
        t_eval: 1-D times (units of the system), starting at the time of ``x0``.
        method: a name in ``hnn.SOLVERS`` (``hnn.register_solver`` adds one), whose ``Solver``
            declares its order, whether it is symplectic, its stability limit and the options it takes
            (``hnn.get_solver(method)``; docs/integrators.md tabulates them). Built in: ``'solve_ivp'``
            (scipy, adaptive; ``scipy_method='RK45'|'DOP853'|...``), ``'dopri5'`` and ``'dop853'``
            (adaptive, in torch, one step size per trajectory), ``'rk4'``, ``'leapfrog'``,
            ``'midpoint'`` and ``'yoshida4'`` (fixed steps: option ``dt``, default one step per
            ``t_eval`` interval; the midpoint, the choice for a learned H, iterates to ``tol``) and
            ``'discrete_gradient'`` (keeps the field's own H exactly: ``f`` must carry it). All accept
            ``stats={}``, filled with ``nfev``, the number of batched evaluations of ``f`` (and
            for the midpoint ``iterations`` and ``max_step_iterations``), and ``max_norm`` (default
            1e6; None to disable): a state with a component beyond it counts as blown up.
            Fixed-step methods take ``t_eval`` in either direction (backwards for reversibility).
        differentiable: False (default): no autograd graph, whatever the caller's grad mode (the
            result does not require grad, memory does not grow with the horizon, and ``f`` runs its
            evaluation path). True: every step is recorded by autograd, in grad mode whatever the
            caller's, so the result can be differentiated with respect to ``x0`` and ``f``'s
            parameters (trajectory training, one-step Jacobians); fixed-step methods only (the
            adaptive ones choose their steps outside autograd).

        rtol, atol: the tolerances of an adaptive method (solve_ivp, dopri5, dop853; a fixed-step method
            takes none). None: 1e-7 and 1e-9 on float64 states, under which the tasks' true systems keep
            their energy to 1e-6 (pendulum) .. 1e-4 (chaotic 3-body) relative over ten training lengths;
            on float32 states 1.2e-5 and 1.2e-7 (100 eps, the tightest float32 honours: tighter, dop853
            took 24x the field calls at 1e-7 on a float32 HNN). ``hnn.integrators.adaptive.default_tolerances``;
            docs/integrators.md, "Default tolerances". (scipy's own 1e-3 / 1e-6 let the true pendulum's
            energy drift 11%.)
        threads: torch's thread count during the rollout (default 1, as every command: a second thread
            slows a shared box many times over, docs/speed.md#threads); the caller's count is restored
            after. None: the caller's count, except one for batches of at most ``SMALL_BATCH_ROWS`` (64)
            states, whose products are too small to share between threads (the library's own calls).

    A learned map (a model that declares ``steps``, ``hnn.models.maps``) is not integrated: it steps
    itself by its ``dt`` on ``t_eval`` of multiples of it (``hnn.integrators.map_steps``; ``method``
    is not read, and of the options only ``dt``, its own, ``max_norm`` and ``stats``).

    Returns:
        ``(batch, len(t_eval), dim)``, with ``x0`` at index 0.

    Raises:
        ValueError: for an unknown ``method`` (naming the registered ones), an option the method does not
            take (naming the ones it does: ``Solver.accepts``), bad ``x0`` or ``t_eval``, or ``x0`` on
            another device than the model's weights.
        DivergenceError: when states or derivatives become non-finite or states exceed
            ``max_norm``, naming the trajectories and times (never a silent NaN);
            ``hnn.ConvergenceError`` (a subclass) when the midpoint iteration does not converge.

    Warns (``UserWarning``) when ``rtol`` (adaptive methods: solve_ivp, dopri5) is below 100 eps
    of ``x0``'s dtype or the midpoint ``tol`` below its eps: tolerances the dtype cannot honour; and
    (``hnn.integrators.stability.StepSizeWarning``) when a fixed-step rollout of 100 steps or more
    (not ``differentiable``) steps past its method's stability limit on the field's fastest mode at
    the starts (``hnn.integrators.stability``), naming dt, the estimate and the fix.
    """
    options.update({name: value for name, value in (("rtol", rtol), ("atol", atol)) if value is not None})
    step_map = step_map_of(f)
    if step_map is not None:        # a learned map steps itself at its dt: no solver
        check_request(step_map, method, _DEFAULT_METHOD, options)
        x0, t = _as_batch(x0, field_device(step_map.step)), _as_t_eval(t_eval)
        with torch_threads(threads if threads is not None else 1 if len(x0) <= SMALL_BATCH_ROWS else None):
            if differentiable:
                with torch.enable_grad():
                    return map_rollout(step_map, x0, t, **options)
            with torch.no_grad(), frozen_weights():     # the weights cannot change: the map may run as a kernel
                return map_rollout(step_map, x0, t, **options)
    solver = get_solver(method)
    solver.check_options(options)
    device = field_device(f)
    owner = getattr(f, "__self__", None)
    if isinstance(owner, Model) and getattr(f, "__func__", None) is getattr(type(owner), "time_derivative", None):
        f = owner           # a model's own field, given as model.time_derivative: step it as the model declares
    if isinstance(f, Model):
        f = f.field
    if type(f) is EnergyField and not solver.needs_hamiltonian:
        # a solver that reads no H steps the plain field: one call less per evaluation; an adaptive one keeps
        # the field's numpy call (it steps in numpy), and calls the field itself only where that does not serve
        f = EnergyField(f.whole, numpy=f.numpy) if solver.adaptive and f.numpy is not None else f.whole
    if differentiable and solver.adaptive:
        raise ValueError(f"{method} chooses its steps outside autograd and cannot give a differentiable rollout; "
                         "use a fixed-step method (rk4, leapfrog, midpoint, yoshida4) with differentiable=True")
    x0 = _as_batch(x0, device)
    _check_tolerance(solver, x0.dtype, options)
    if solver.adaptive:
        options = dict(zip(("rtol", "atol"), default_tolerances(x0.dtype))) | options
    t = _as_t_eval(t_eval)
    with torch_threads(threads if threads is not None else 1 if len(x0) <= SMALL_BATCH_ROWS else None):
        if differentiable:
            with torch.enable_grad():
                return solver.run(f, x0, t, **options)
        with torch.no_grad(), frozen_weights():     # the weights cannot change: fields may run as kernels
            if not in_model_axis():         # a step past the method's stability limit: one warning, not silence
                warn_if_unstable(solver, f, x0, t, options)
            return solver.run(f, x0, t, **options)


# a learned map takes no method: any but the default one is refused (check_request)
_DEFAULT_METHOD = inspect.signature(rollout).parameters["method"].default
