"""Fixed-step integrators in torch, run by one driver (``fixed_step_rollout``) on a batch
``x = [q, p]`` ``(batch, 2n)`` through the field ``f(x) -> dxdt`` alone (``hnn.rollout(method=...)``):

- ``'rk4'``: classic, order 4, not symplectic.
- ``'leapfrog'`` (Stormer-Verlet, kick-drift-kick), order 2, two ``f`` calls a step; it reads only
  one half of ``f`` at each stage, so it is symplectic and reversible only for a separable
  H = T(p) + V(q) (every task's true dynamics; a learned HNN's H is generally not: use midpoint).
- ``'midpoint'`` (implicit), order 2, symplectic and symmetric for any H:
  ``x1 = x0 + dt f((x0 + x1) / 2)``, solved by fixed-point iteration to ``tol`` (``ImplicitStepper``,
  which the discrete gradient shares).
- ``'yoshida4'``: three steps of a symmetric order-2 base (leapfrog or midpoint), weights w1, w0,
  w1 below, order 4, still symplectic and symmetric.

Each interval of ``t_eval`` is cut into equal steps no longer than ``dt`` (default one a step),
signed like ``t_eval`` (backwards too). Each method is a ``Stepper`` (``step(x, h)``); the driver
checks the states, so every method reports blow-ups alike; a new one is a subclass and one
``hnn.integrators.solvers.register_solver`` call.
"""
from __future__ import annotations

import math
import warnings
from typing import Callable

import numpy as np
import torch

from ..errors import ConvergenceError, divergence_error
from ..interface import SplitField
from ..modes import in_model_axis

Field = Callable[[torch.Tensor], torch.Tensor]

# Yoshida (1990): a symmetric composition S(w1 h) S(w0 h) S(w1 h) of a symmetric order-2 step S
# is order 4 when 2 w1 + w0 = 1 (consistency) and 2 w1^3 + w0^3 = 0 (the h^3 error cancels), so
# w0 = -2^(1/3) w1 and w1 (2 - 2^(1/3)) = 1. Read at call time, so a test can perturb them.
_CBRT2 = 2.0 ** (1.0 / 3.0)
YOSHIDA_WEIGHTS = (1.0 / (2.0 - _CBRT2), -_CBRT2 / (2.0 - _CBRT2), 1.0 / (2.0 - _CBRT2))


def default_tol(dtype: torch.dtype) -> float:
    """The midpoint iteration's default tolerance: 1e-12 in float64, a few ulps in float32."""
    return max(1e-12, 8 * torch.finfo(dtype).eps)


def rk4_step(f: Field, x: torch.Tensor, dt) -> torch.Tensor:
    """The classic RK4 increment ``x(t + dt) - x(t)`` of dx/dt = f(x); ``dt`` a float or ``(batch, 1)``."""
    if not torch.is_tensor(dt):
        return _rk4_increment(f, x, float(dt))
    k1 = f(x)
    k2 = f(x + dt / 2 * k1)
    k3 = f(x + dt / 2 * k2)
    k4 = f(x + dt * k3)
    return dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _rk4_increment(f: Field, x: torch.Tensor, h: float) -> torch.Tensor:
    """``rk4_step`` for a float step: each stage state and the weighted sum in one fused op apiece."""
    k1 = f(x)
    k2 = f(torch.add(x, k1, alpha=h / 2))
    k3 = f(torch.add(x, k2, alpha=h / 2))
    k4 = f(torch.add(x, k3, alpha=h))
    return torch.add(k1, k2, alpha=2).add_(k3, alpha=2).add_(k4).mul_(h / 6)


def separable_halves(f: Field):
    """``(dT/dp, dV/dq)`` as two functions of ``(batch, n)`` halves when ``f`` is a
    ``hnn.interface.SplitField`` (a separable model's ``field``), so a stage that reads one half of
    the field evaluates only that half; else None."""
    return (f.kinetic_gradient, f.potential_gradient) if isinstance(f, SplitField) else None


class Stepper:
    """One fixed-step method on a batch ``x`` of shape ``(batch, dim)``: all the driver sees of it.

    A subclass implements ``step`` and counts its batched calls of ``f`` in ``nfev``. Every
    stepper is built as ``Stepper(f, dim, dtype, tol=, max_iter=, base=)`` by the one driver
    (``fixed_step_rollout``); what a user may pass is each method's ``Solver.options``, and
    ``rollout`` refuses the rest (a ``tol`` given to rk4), so an explicit stepper sees them unset.
    """

    def __init__(self, f: Field, dim: int, dtype: torch.dtype, **options):
        self.f, self.nfev = f, 0

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        """``x`` ``(batch, dim)`` one step of (signed) size ``h`` later."""
        raise NotImplementedError

    def reset(self, x: torch.Tensor) -> None:
        """Forget what is carried from step to step: rows of ``x`` were replaced."""

    def take_failed(self) -> torch.Tensor | None:
        """``(batch,)`` rows whose implicit equation was not solved since the last call; None if none can
        fail (a stepper that can fail also gives ``convergence_error(method, rows, times, others)``)."""
        return None

    def stats(self) -> dict:
        """What ``rollout(stats={})`` reports: ``nfev``, the number of batched ``f`` calls."""
        return {"nfev": self.nfev}


class RK4(Stepper):
    """The classic (non-symplectic) RK4 step."""

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        self.nfev += 4
        return x + _rk4_increment(self.f, x, h)


class Leapfrog(Stepper):
    """Kick-drift-kick; keeps dp/dt at the current q between calls (exact for separable H).

    On a field that offers its two halves (``separable_halves``) each step evaluates one dT/dp and
    one dV/dq, the dV/dq carried to the next step; otherwise each step calls the whole field twice
    and reads half of each. ``nfev`` counts whole-field calls, a half counting one half.
    """

    def __init__(self, f: Field, dim: int, dtype: torch.dtype, **options):
        if dim % 2:
            raise ValueError(f"leapfrog needs x = [q, p] of even dimension, got dim={dim}; use method='midpoint'")
        super().__init__(f, dim, dtype)
        self.n, self.accel = dim // 2, None
        self.halves = separable_halves(f)
        self._half_calls = 0

    @property
    def nfev(self) -> int:
        return self._nfev + self._half_calls // 2

    @nfev.setter
    def nfev(self, value: int) -> None:
        self._nfev = value

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        n = self.n
        if self.halves is not None:
            kinetic, potential = self.halves
            q, p = x[:, :n], x[:, n:]
            if self.accel is None:
                self.accel = potential(q)            # dV/dq: dp/dt = -dV/dq
                self._half_calls += 1
            p_half = torch.add(p, self.accel, alpha=-h / 2)
            q_new = torch.add(q, kinetic(p_half), alpha=h)
            self.accel = potential(q_new)
            self._half_calls += 2
            return torch.cat([q_new, p_half.sub_(self.accel, alpha=h / 2) if not p_half.requires_grad
                              else p_half - (h / 2) * self.accel], dim=1)
        q, p = x[:, :n], x[:, n:]
        if self.accel is None:
            self.accel = self.f(x)[:, n:]
            self.nfev += 1
        p_half = p + (h / 2) * self.accel
        q_new = q + h * self.f(torch.cat([q, p_half], dim=1))[:, :n]      # dq/dt at p_half
        self.accel = self.f(torch.cat([q_new, p_half], dim=1))[:, n:]     # dp/dt at q_new
        self.nfev += 2
        return torch.cat([q_new, p_half + (h / 2) * self.accel], dim=1)

    def reset(self, x: torch.Tensor) -> None:
        self.accel = None         # the cached dp/dt belongs to the replaced rows too


class ImplicitStepper(Stepper):
    """A step x1 = x0 + h g(x0, x1) solved by fixed-point iteration to ``tol`` (relative to
    max(|x|, 1); default ``default_tol``), at most ``max_iter`` iterations a step: the loop, the
    counters and the convergence report that the implicit methods share (``Midpoint``,
    ``hnn.integrators.discrete_gradient.DiscreteGradient``). A subclass gives ``update`` (the iteration's map),
    the first iterate, and ``name`` and ``equation`` for its errors."""

    name, equation = "implicit", "x1 = x0 + h g(x0, x1)"

    def __init__(self, f: Field, dim: int, dtype: torch.dtype, tol: float | None = None, max_iter: int = 100,
                 **options):
        super().__init__(f, dim, dtype)
        self.tol = default_tol(dtype) if tol is None else tol
        if not (self.tol > 0 and math.isfinite(self.tol)):
            raise ValueError(f"{self.name} needs a positive finite tol, got {tol!r}")
        if self.tol < torch.finfo(dtype).eps:
            # stacklevel 5: rollout's caller, past this __init__, the subclass's, the driver and rollout
            # (for yoshida4's base, one frame deeper: rollout)
            warnings.warn(f"{self.name} tol={self.tol:g} is below the machine epsilon of {dtype} "
                          f"({torch.finfo(dtype).eps:.3g}): the iteration cannot reach it; use tol >= "
                          f"{default_tol(dtype):.3g} or float64 states", stacklevel=5)
        if not (isinstance(max_iter, int) and max_iter >= 1):
            raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
        self.max_iter = max_iter
        self.iterations = self.max_step_iterations = 0
        self.failed = None          # (batch,) rows whose iteration did not converge in the current interval

    def update(self, x: torch.Tensor, x1: torch.Tensor, h: float) -> torch.Tensor:
        """The next iterate x0 + h g(x0, x1), ``(batch, dim)``."""
        raise NotImplementedError

    def solve(self, x: torch.Tensor, x1: torch.Tensor, h: float) -> torch.Tensor:
        """Iterate ``update`` from the first iterate ``x1`` until the change is below tol; rows that do not
        get there in ``max_iter`` are marked failed (``take_failed``)."""
        graph = torch.is_grad_enabled()     # a differentiable rollout: the checks stay off the graph
        bound = (x.detach() if graph else x).abs().clamp_(min=1.0).mul_(self.tol)
        for k in range(1, self.max_iter + 1):  # noqa: B007 (k counts the iterations after the loop)
            x_next = self.update(x, x1, h)
            self.nfev += 1
            # converged where the update is below tol (relative to max(|x|, 1)); non-finite rows are
            # not "unconverged": the divergence check reports them (NaN and inf updates count as 0).
            # excess = |update| - bound, one reduction an iteration
            excess = torch.sub(x_next.detach(), x1.detach()) if graph else torch.sub(x_next, x1)
            excess.abs_().nan_to_num_(0.0, 0.0, 0.0).sub_(bound)
            x1 = x_next
            if float(excess.max()) <= 0:
                break
        else:
            failed = (excess > 0).any(dim=1)
            self.failed = failed if self.failed is None else self.failed | failed
        self.iterations += k
        self.max_step_iterations = max(self.max_step_iterations, k)
        return x1

    def take_failed(self) -> torch.Tensor | None:
        failed, self.failed = self.failed, None
        return failed

    def stats(self) -> dict:
        # iterations: fixed-point iterations over all steps; max_step_iterations: the most in one step
        return {"nfev": self.nfev, "iterations": self.iterations, "max_step_iterations": self.max_step_iterations}

    def convergence_error(self, method: str, rows: list, times: list, others: int) -> ConvergenceError:
        shown = ", ".join(f"#{i} at t={s:.4g}" for i, s in zip(rows[:10], times[:10]))
        also = f" ({others} other trajectories diverged)" if others else ""
        return ConvergenceError(
            f"{method}: the fixed-point iteration {self.equation} did not converge to tol={self.tol:g} in "
            f"max_iter={self.max_iter} iterations for {len(rows)} trajectories: {shown}{also}. It needs "
            "dt * (Lipschitz constant of the field) below about 2: reduce dt (or raise max_iter).", rows, times)


MIDPOINT_HISTORY = 7         # increments the midpoint's first guess extrapolates (read at call time)
# the extrapolation weights for m increments, newest first: (-1)^(j+1) binomial(m, j)
_EXTRAPOLATION = {m: tuple((-1) ** (j + 1) * math.comb(m, j) for j in range(1, m + 1)) for m in range(1, 9)}


class Midpoint(ImplicitStepper):
    """Implicit midpoint by fixed-point iteration, started from the previous increments extrapolated
    (Euler at first)."""

    name, equation = "midpoint", "x1 = x0 + h f((x0 + x1) / 2)"

    def __init__(self, f: Field, dim: int, dtype: torch.dtype, tol: float | None = None, max_iter: int = 100,
                 **options):
        super().__init__(f, dim, dtype, tol, max_iter)
        # slot -> (h, [x1 - x of its last steps of size h, newest first]): the next guess. A
        # composition sets ``slot`` to the substep's position, so each position extrapolates its own
        # sequence (equally spaced in time, one a step) instead of its neighbours'
        self.last, self.slot = {}, 0

    def _guess(self, x: torch.Tensor, h: float) -> torch.Tensor:
        """The first iterate. The increment x(t + h) - x(t) is smooth in t, so the last m increments
        of the same step size extrapolate it by a polynomial of degree m - 1, off by O(h^(m+1)):
        sum_j (-1)^(j+1) binomial(m, j) d_j, newest d_1. After a change of step size, the last
        one rescaled (O(h^2)), as in a differentiable rollout; at the start, explicit Euler (O(h^2))."""
        if self.slot not in self.last:
            if self.last:           # a composition's later substep: the previous substep's increment
                h_last, increments = next(reversed(self.last.values()))
                return torch.add(x, increments[0], alpha=h / h_last)
            self.nfev += 1
            return torch.add(x, self.f(x), alpha=h)
        h_last, increments = self.last[self.slot]
        # a differentiable rollout differentiates the unrolled iteration, whose gradient nears the
        # fixed point's only with the iterations a good guess saves: it keeps the rescaled last increment
        if h_last != h or torch.is_grad_enabled():
            return torch.add(x, increments[0], alpha=h / h_last)
        x1 = x.clone()
        for d, weight in zip(increments, _EXTRAPOLATION[len(increments)]):
            x1.add_(d, alpha=weight)
        return x1

    def update(self, x: torch.Tensor, x1: torch.Tensor, h: float) -> torch.Tensor:
        return torch.add(x, self.f(torch.lerp(x, x1, 0.5)), alpha=h)

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        x1 = self.solve(x, self._guess(x, h), h)
        graph = torch.is_grad_enabled()
        # detached: the converged x1 does not depend on the guess
        increment = torch.sub(x1, x).detach() if graph else torch.sub(x1, x)
        h_last, increments = self.last.get(self.slot, (None, []))
        self.last[self.slot] = (h, [increment, *increments[:MIDPOINT_HISTORY - 1]] if h_last == h else [increment])
        return x1

    def reset(self, x: torch.Tensor) -> None:
        self.last = {}


_YOSHIDA_BASES = {"leapfrog": Leapfrog, "midpoint": Midpoint}


class Yoshida4(Stepper):
    """Yoshida's order-4 composition of a symmetric order-2 base: ``base='leapfrog'`` (default) or ``'midpoint'``.

    The base does the work: its state, failures and counts are the composition's.
    """

    def __init__(self, f: Field, dim: int, dtype: torch.dtype, base: str | None = None, **options):
        base = base or "leapfrog"
        if base not in _YOSHIDA_BASES:
            raise ValueError(f"yoshida4's base must be 'leapfrog' or 'midpoint', got {base!r}")
        self.base = _YOSHIDA_BASES[base](f, dim, dtype, **options)     # no state of its own

    @property
    def nfev(self) -> int:
        return self.base.nfev

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        for i, w in enumerate(YOSHIDA_WEIGHTS):
            self.base.slot = i      # the midpoint base extrapolates each substep from its own history
            x = self.base.step(x, w * h)
        return x

    def reset(self, x: torch.Tensor) -> None:
        self.base.reset(x)

    def take_failed(self) -> torch.Tensor | None:
        return self.base.take_failed()

    def stats(self) -> dict:
        return self.base.stats()

    def convergence_error(self, *args) -> ConvergenceError:
        return self.base.convergence_error(*args)


def _steps(span: float, dt: float | None) -> int:
    """How many equal steps no longer than ``dt`` cover ``span`` (1 without ``dt``)."""
    return 1 if dt is None else max(1, math.ceil(abs(span) / dt - 1e-9))


def _blown(x: torch.Tensor, max_norm: float | None) -> torch.Tensor:
    """``(batch,)`` rows of ``x`` that are non-finite or have a component beyond ``max_norm``."""
    bad = ~torch.isfinite(x).all(dim=1)
    if max_norm is not None:
        bad |= ~(x.detach().abs() <= max_norm).all(dim=1)
    return bad


def fixed_step_rollout(f: Field, x0: torch.Tensor, t: np.ndarray, method: str, stepper: type[Stepper],
                       dt: float | None = None, max_norm: float | None = 1e6, tol: float | None = None,
                       max_iter: int = 100, base: str | None = None, stats: dict | None = None) -> torch.Tensor:
    """``(batch, len(t), dim)`` by fixed steps of ``stepper`` (a ``Stepper`` class), called ``method`` in messages.

    ``dt`` (positive, units of t) caps the step; the sign comes from ``t``. ``tol`` and
    ``max_iter`` control the midpoint iteration (also yoshida4 with ``base='midpoint'``).
    Runs in the caller's grad mode, so a step can be differentiated (e.g. its Jacobian).
    Rows blowing up (non-finite, or a component beyond ``max_norm``) are recorded at the first
    ``t`` sample where they are found and the others finish; then ``DivergenceError`` names them.
    A midpoint iteration that does not converge raises ``ConvergenceError`` the same way.
    """
    if dt is not None and not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"{method} needs a positive finite dt (the direction comes from t_eval), got {dt!r}")
    stepper = stepper(f, x0.shape[1], x0.dtype, tol=tol, max_iter=max_iter, base=base)
    out, x = [x0], x0
    first_bad = torch.full((len(x0),), float("nan"), dtype=torch.float64, device=x0.device)
    not_converged = torch.full((len(x0),), float("nan"), dtype=torch.float64, device=x0.device)
    for k in range(len(t) - 1):
        span = t[k + 1] - t[k]
        n = _steps(span, dt)
        for _ in range(n):
            x = stepper.step(x, span / n)
        if not in_model_axis():     # vmap over models cannot branch on a value: their losses are checked
            x = _retire_failed_rows(stepper, x, float(t[k + 1]), max_norm, first_bad, not_converged)
        out.append(x)
    if stats is not None:
        stats.update(stepper.stats())
    _raise_failures(stepper, method, dt, max_norm, first_bad, not_converged)
    return torch.stack(out, dim=1)


def _retire_failed_rows(stepper: Stepper, x: torch.Tensor, time: float, max_norm: float | None,
                        first_bad: torch.Tensor, not_converged: torch.Tensor) -> torch.Tensor:
    """``x`` with the rows that failed by ``time`` zeroed; each row's first failure time is
    written into ``first_bad`` (blew up) or ``not_converged`` (its implicit step failed), both ``(batch,)``."""
    bad = _blown(x, max_norm)
    stuck = torch.zeros_like(bad)
    failed = stepper.take_failed()
    if failed is not None:
        # an iteration that failed to converge is the cause, whatever the state did next
        stuck = failed & torch.isnan(not_converged) & torch.isnan(first_bad)
        not_converged[stuck] = time
        bad &= ~failed
    new = bad & torch.isnan(first_bad) & torch.isnan(not_converged)
    first_bad[new] = time
    if (new | stuck).any():
        x = torch.where((new | stuck)[:, None], torch.zeros_like(x), x)   # keep the dead rows from overflowing
        stepper.reset(x)
    return x


def _raise_failures(stepper: Stepper, method: str, dt, max_norm, first_bad: torch.Tensor,
                    not_converged: torch.Tensor) -> None:
    """Raise ``ConvergenceError`` for rows stuck in an implicit step, else ``DivergenceError`` for blown ones."""
    diverged = torch.nonzero(~torch.isnan(first_bad)).flatten().tolist()
    stuck = torch.nonzero(~torch.isnan(not_converged)).flatten().tolist()
    if stuck:
        raise stepper.convergence_error(method, stuck, not_converged[stuck].tolist(), len(diverged))
    if diverged:
        raise divergence_error(f"{method} (dt={dt}, max_norm={max_norm})", diverged, first_bad[diverged].tolist())
