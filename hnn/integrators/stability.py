"""The fixed-step solvers' stability limits, and the warning ``hnn.rollout`` gives past one.

An explicit method of step dt stays bounded on a mode with eigenvalue lambda of the field's Jacobian only
while lambda dt lies inside its stability region; past it the path grows (or, inside but near it,
decays) by orders of magnitude while the state stays finite, and nothing raises: a learned model
rolled out that way degrades without an error. So before a long fixed-step rollout ``warn_if_unstable``
estimates the Jacobian's spectral radius at the starts (central differences, one batched call of the
field) and warns once where dt times it passes the method's limit, naming dt, the estimate and the fix.

The limits are on the imaginary axis, where a Hamiltonian field's modes lie near a center (lambda =
+-i omega): RK4 |lambda dt| < 2 sqrt 2, leapfrog 2, Yoshida's order 4 on leapfrog 1.5734 (the largest
omega dt at which its one-step matrix on the harmonic oscillator keeps |trace| <= 2;
``tests/test_stability_warning.py`` measures each on the exact oscillator). Each ``Solver`` declares its
own (``stability_limit``); the implicit methods (midpoint, discrete_gradient, yoshida4 on midpoint) and
the adaptive ones have none.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import torch

# on the imaginary axis (the numbers the solvers' registry declares)
RK4_LIMIT, LEAPFROG_LIMIT, YOSHIDA4_LIMIT = 2 * math.sqrt(2), 2.0, 1.5734064
# checked only where it costs little against the rollout itself: at least this many steps, a state of
# at most this width (2 width evaluations per start), at most this many starts
MIN_STEPS, MAX_DIM, MAX_STARTS = 100, 64, 16


class StepSizeWarning(UserWarning):
    """A fixed-step rollout whose dt passes its method's stability limit on the field's fastest mode."""


def spectral_radius(f, x0: torch.Tensor) -> float:
    """The largest |eigenvalue| of the Jacobian of ``f`` ``(batch, dim) -> (batch, dim)`` over the rows of
    ``x0`` ``(batch, dim)``, by central differences of one batched call (steps eps^(1/3) times each
    component's size, at least 1)."""
    batch, dim = x0.shape
    eps = torch.finfo(x0.dtype).eps
    h = eps ** (1 / 3) * x0.abs().clamp(min=1.0)                        # (batch, dim)
    steps = torch.diag_embed(h)                                        # (batch, dim, dim): row j moves component j
    plus, minus = (x0[:, None, :] + s * steps for s in (1, -1))
    values = f(torch.cat([plus, minus]).reshape(2 * batch * dim, dim)).reshape(2, batch, dim, dim)
    jacobian = ((values[0] - values[1]) / (2 * h[:, :, None])).transpose(1, 2)     # d f_i / d x_j
    eig = np.linalg.eigvals(jacobian.detach().cpu().double().numpy())
    finite = np.isfinite(eig).all(axis=1)
    return float(np.abs(eig[finite]).max()) if finite.any() else math.inf


def warn_if_unstable(solver, f, x0: torch.Tensor, t: np.ndarray, options: dict) -> float | None:
    """Warn (``StepSizeWarning``) where the largest step of a fixed-step rollout of ``f`` over ``t`` from
    ``x0`` times the field's spectral radius at the starts passes ``solver``'s limit (``Solver.limit``);
    returns that product, or None where nothing was checked (no limit, a short rollout, a wide state)."""
    method, limit = solver.name, solver.limit(options)
    if limit is None or x0.shape[1] > MAX_DIM:
        return None
    spans = np.abs(np.diff(t))
    dt = options.get("dt")
    counts = np.ones(len(spans)) if dt is None else np.maximum(1, np.ceil(spans / dt - 1e-9))
    if counts.sum() < MIN_STEPS:
        return None
    step = float((spans / counts).max())
    radius = spectral_radius(f, x0[:MAX_STARTS])
    product = radius * step
    if product > limit:
        warnings.warn(f"{method} at dt = {step:.3g}: the field's fastest mode at the starts has |lambda| = "
                      f"{radius:.3g} (the spectral radius of its Jacobian), so |lambda| dt = {product:.3g} passes "
                      f"{method}'s stability limit {limit:.3g}; the path can grow or decay by orders of magnitude "
                      f"without an error. Use dt below {limit / radius:.3g}, or an implicit method (midpoint, "
                      "discrete_gradient) or an adaptive one (dopri5)", StepSizeWarning, stacklevel=3)
    return product
