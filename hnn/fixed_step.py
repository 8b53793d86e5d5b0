"""Fixed-step symplectic integrators in torch: leapfrog, implicit midpoint and Yoshida's 4th order.

All three act on a batch ``x = [q, p]`` of shape ``(batch, 2n)`` through the vector field
``f(x) -> dxdt`` alone, and are reached through ``hnn.rollout(..., method=...)``:

- ``'leapfrog'`` (Stormer-Verlet, kick-drift-kick), order 2, two ``f`` calls a step. It reads
  only the ``q`` half of ``f`` at states where ``p`` has just changed and only the ``p`` half
  where ``q`` has, so it is exact (symplectic, reversible) only for separable H = T(p) + V(q),
  as in every task's true dynamics. A learned HNN's H is generally not separable: use
  ``'midpoint'`` for learned models.
- ``'midpoint'`` (implicit midpoint rule), order 2, symplectic and symmetric for any H:
  ``x1 = x0 + dt f((x0 + x1) / 2)``, solved by fixed-point iteration to ``tol``.
- ``'yoshida4'``: three steps of a symmetric order-2 base (leapfrog or midpoint) with the
  weights w1, w0, w1 below, order 4, still symplectic and symmetric.

Steps are fixed: each interval of ``t_eval`` is cut into equal steps no longer than ``dt``
(default one step per interval), signed like ``t_eval`` so integration runs backwards too.
``rollout(method='rk4')`` (classic, not symplectic) runs through the same driver,
``fixed_step_rollout``, so every fixed-step method reports blow-ups the same way.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import torch

from .integrate import DivergenceError, _divergence, rk4_step

# Yoshida (1990): a symmetric composition S(w1 h) S(w0 h) S(w1 h) of a symmetric order-2 step S
# is order 4 when 2 w1 + w0 = 1 (consistency) and 2 w1^3 + w0^3 = 0 (the h^3 error cancels), so
# w0 = -2^(1/3) w1 and w1 (2 - 2^(1/3)) = 1. Read at call time, so a test can perturb them.
_CBRT2 = 2.0 ** (1.0 / 3.0)
YOSHIDA_WEIGHTS = (1.0 / (2.0 - _CBRT2), -_CBRT2 / (2.0 - _CBRT2), 1.0 / (2.0 - _CBRT2))

SYMPLECTIC_METHODS = ("leapfrog", "midpoint", "yoshida4")


class ConvergenceError(DivergenceError):
    """The implicit midpoint's fixed-point iteration did not converge; ``trajectories``, ``times`` say where.

    A ``DivergenceError``, so code that catches failed rollouts catches this one too.
    """


def default_tol(dtype: torch.dtype) -> float:
    """The midpoint iteration's default tolerance: 1e-12 in float64, a few ulps in float32."""
    return max(1e-12, 8 * torch.finfo(dtype).eps)


class _Leapfrog:
    """Kick-drift-kick; keeps dp/dt at the current q between calls (exact for separable H)."""

    def __init__(self, f, dim: int):
        if dim % 2:
            raise ValueError(f"leapfrog needs x = [q, p] of even dimension, got dim={dim}; use method='midpoint'")
        self.f, self.n, self.nfev, self.accel = f, dim // 2, 0, None

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        n = self.n
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
        """Forget the cached dp/dt (call after rows of ``x`` were replaced)."""
        self.accel = None


class _Midpoint:
    """Implicit midpoint by fixed-point iteration, started from the previous increment (Euler at first)."""

    def __init__(self, f, dim: int, tol: float, max_iter: int):
        self.f, self.tol, self.max_iter = f, tol, max_iter
        self.nfev = self.iterations = self.max_step_iterations = 0
        self.failed = None          # (batch,) rows whose iteration did not converge in the current interval
        self.last = None            # (h, x1 - x) of the previous step: the next step's first guess

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        if self.last is None:
            x1 = x + h * self.f(x)          # explicit Euler: off by O(h^2)
            self.nfev += 1
        else:                               # the last increment, rescaled: off by O(h^2) too, and free
            x1 = x + (h / self.last[0]) * self.last[1]
        scale = x.detach().abs().clamp(min=1.0)
        for k in range(1, self.max_iter + 1):  # noqa: B007 (k counts the iterations after the loop)
            x_next = x + h * self.f((x + x1) / 2)
            self.nfev += 1
            delta = (x_next.detach() - x1.detach()).abs()
            x1 = x_next
            # converged where the update is below tol (relative to max(|x|, 1)); non-finite rows are
            # not "unconverged": the divergence check reports them
            ok = ((delta <= self.tol * scale) | ~torch.isfinite(delta)).all(dim=1)
            if ok.all():
                break
        else:
            self.failed = ~ok if self.failed is None else self.failed | ~ok
        self.iterations += k
        self.max_step_iterations = max(self.max_step_iterations, k)
        self.last = (h, (x1 - x).detach())     # detached: the converged x1 does not depend on the guess
        return x1

    def reset(self, x: torch.Tensor) -> None:
        self.last = None


class _RK4:
    """The classic (non-symplectic) RK4 step, run by the same fixed-step driver."""

    def __init__(self, f):
        self.f, self.nfev = f, 0

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        self.nfev += 4
        return x + rk4_step(self.f, x, h)

    def reset(self, x: torch.Tensor) -> None:
        pass


class _Yoshida:
    """Yoshida's order-4 composition of a symmetric base step."""

    def __init__(self, base):
        self.base = base

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        for w in YOSHIDA_WEIGHTS:
            x = self.base.step(x, w * h)
        return x

    def reset(self, x: torch.Tensor) -> None:
        self.base.reset(x)


def _make_stepper(method: str, f, dim: int, dtype: torch.dtype, tol, max_iter: int, base: str | None):
    base = base or "leapfrog"
    if method == "yoshida4" and base not in ("leapfrog", "midpoint"):
        raise ValueError(f"yoshida4's base must be 'leapfrog' or 'midpoint', got {base!r}")
    if method == "midpoint" or (method == "yoshida4" and base == "midpoint"):
        if tol is None:
            tol = default_tol(dtype)
        if not (tol > 0 and math.isfinite(tol)):
            raise ValueError(f"midpoint needs a positive finite tol, got {tol!r}")
        if tol < torch.finfo(dtype).eps:
            warnings.warn(f"midpoint tol={tol:g} is below the machine epsilon of {dtype} "
                          f"({torch.finfo(dtype).eps:.3g}): the iteration cannot reach it; use tol >= "
                          f"{default_tol(dtype):.3g} or float64 states", stacklevel=4)
        if not (isinstance(max_iter, int) and max_iter >= 1):
            raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
    if method == "rk4":
        return _RK4(f)
    if method == "leapfrog":
        return _Leapfrog(f, dim)
    if method == "midpoint":
        return _Midpoint(f, dim, tol, max_iter)
    return _Yoshida(_Leapfrog(f, dim) if base == "leapfrog" else _Midpoint(f, dim, tol, max_iter))


def fixed_step_rollout(f, x0: torch.Tensor, t: np.ndarray, method: str, dt: float | None = None,
                       max_norm: float | None = 1e6, tol: float | None = None, max_iter: int = 100,
                       base: str | None = None, stats: dict | None = None) -> torch.Tensor:
    """``(batch, len(t), dim)`` by fixed steps of ``method`` (the symplectic ones of the module
    docstring, or ``'rk4'``).

    ``dt`` (positive, units of t) caps the step; the sign comes from ``t``. ``tol`` and
    ``max_iter`` control the midpoint iteration (also yoshida4 with ``base='midpoint'``).
    Runs in the caller's grad mode, so a step can be differentiated (e.g. its Jacobian).
    Rows blowing up (non-finite, or a component beyond ``max_norm``) are recorded at the first
    ``t`` sample where they are found and the others finish; then ``DivergenceError`` names them.
    A midpoint iteration that does not converge raises ``ConvergenceError`` the same way.
    """
    if dt is not None and not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"{method} needs a positive finite dt (the direction comes from t_eval), got {dt!r}")
    stepper = _make_stepper(method, f, x0.shape[1], x0.dtype, tol, max_iter, base)
    core = stepper.base if isinstance(stepper, _Yoshida) else stepper     # the order-2 step doing the work
    out, x = [x0], x0
    first_bad = torch.full((len(x0),), float("nan"), dtype=torch.float64)
    not_converged = torch.full((len(x0),), float("nan"), dtype=torch.float64)
    for k in range(len(t) - 1):
        span = t[k + 1] - t[k]
        n = 1 if dt is None else max(1, math.ceil(abs(span) / dt - 1e-9))
        h = span / n
        for _ in range(n):
            x = stepper.step(x, h)
        bad = ~torch.isfinite(x).all(dim=1)
        if max_norm is not None:
            bad |= ~(x.detach().abs() <= max_norm).all(dim=1)
        if isinstance(core, _Midpoint) and core.failed is not None:
            # an iteration that failed to converge is the cause, whatever the state did next
            stuck = core.failed & torch.isnan(not_converged) & torch.isnan(first_bad)
            not_converged[stuck] = float(t[k + 1])
            bad &= ~core.failed
            core.failed = None
        else:
            stuck = torch.zeros_like(bad)
        new = bad & torch.isnan(first_bad) & torch.isnan(not_converged)
        first_bad[new] = float(t[k + 1])
        if (new | stuck).any():
            x = torch.where((new | stuck)[:, None], torch.zeros_like(x), x)   # keep the dead rows from overflowing
            stepper.reset(x)
        out.append(x)
    if stats is not None:
        stats["nfev"] = core.nfev
        if isinstance(core, _Midpoint):
            stats["iterations"] = core.iterations                  # fixed-point iterations, all steps
            stats["max_step_iterations"] = core.max_step_iterations
    diverged = torch.nonzero(~torch.isnan(first_bad)).flatten().tolist()
    stuck = torch.nonzero(~torch.isnan(not_converged)).flatten().tolist()
    if stuck:
        times = not_converged[stuck].tolist()
        shown = ", ".join(f"#{i} at t={s:.4g}" for i, s in zip(stuck[:10], times[:10]))
        also = f" ({len(diverged)} other trajectories diverged)" if diverged else ""
        raise ConvergenceError(
            f"{method}: the implicit midpoint iteration did not converge to tol={core.tol:g} in "
            f"max_iter={max_iter} iterations for {len(stuck)} trajectories: {shown}{also}. The fixed-point "
            "iteration needs dt * (Lipschitz constant of f) < 2: reduce dt (or raise max_iter).", stuck, times)
    if diverged:
        raise _divergence(f"{method} (dt={dt}, max_norm={max_norm})", diverged, first_bad[diverged].tolist())
    return torch.stack(out, dim=1)

