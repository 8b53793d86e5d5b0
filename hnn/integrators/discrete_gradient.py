"""The discrete-gradient method: an implicit integrator that conserves a field's own H exactly.

For dx/dt = S grad H(x) with S skew, a discrete gradient grad-bar H(x0, x1) is any function with
grad-bar H(x0, x1) . (x1 - x0) = H(x1) - H(x0) and grad-bar H(x, x) = grad H(x). The step

    x1 = x0 + h S grad-bar H(x0, x1)

then keeps H(x1) = H(x0) (H(x1) - H(x0) = h grad-bar . S grad-bar = 0 for skew S), in discrete
time, for any step size: not up to a bounded oscillation as a symplectic method, but exactly (to
the tolerance of the implicit solve). A symmetric discrete gradient makes it order 2. It is not
symplectic in general.

Which discrete gradient: where the field brings one in closed form (``EnergyField.discrete_gradient``,
the paper's tanh HNN: the chain rule of difference quotients that DGNet, Matsubara, Ishikawa &
Yaguchi 2020, computes by its "automatic discrete differentiation", ``hnn.models.tanh_mlp.discrete_gradient``),
that one; otherwise Gonzalez's midpoint discrete gradient (1996), built from H alone:

    grad-bar H = grad H(m) + [(H(x1) - H(x0) - grad H(m) . d) / |d|^2] d,  m = (x0 + x1) / 2, d = x1 - x0.

Both are symmetric (order 2). The solver (``method='discrete_gradient'``) needs the field's H: pass
an ``hnn.Model`` that declares ``conservative`` (``hnn.rollout(model, ...)``, whose ``field`` is an
``hnn.interface.EnergyField``), or an ``EnergyField(f, hamiltonian)`` of a known system.
"""
from __future__ import annotations

from typing import Callable

import torch

from .fixed_step import ImplicitStepper, default_tol
from ..interface import EnergyField, gradient_of
from ..modes import in_model_axis


def gonzalez(hamiltonian: Callable, x0: torch.Tensor, x1: torch.Tensor) -> torch.Tensor:
    """Gonzalez's midpoint discrete gradient of ``hamiltonian`` ``(batch, dim) -> (batch,)`` between
    ``x0`` and ``x1`` ``(batch, dim)``; ``(batch, dim)``. In grad mode it can be differentiated (training).

    Its quotient's numerator H(x1) - H(x0) - grad H(m) . d is O(|d|^3), a difference of H's values
    that round at eps |H|; over |d|^2, times d, times the step h ~ |d| / |grad H|, that rounding moves
    a step's x1 by about eps |H| / |grad H|, whatever the step. Where that passes the implicit solve's
    default tolerance (``default_tol`` relative to max(|x|, 1): in float32 where |H| is above about
    twice |grad H| |x|, as with a large constant in H, which moves no state; in float64 about a
    thousand times), the fixed point would be noise: H(x1) - H(x0) is taken there as the 3-point
    Gauss-Legendre quadrature of grad H . d along the step, which rounds at eps |grad H| |d| and is
    off by O(|d|^7).
    """
    m, d = 0.5 * (x0 + x1), x1 - x0
    grad = gradient_of(hamiltonian, m)
    dd = (d * d).sum(1, keepdim=True)
    h0, h1 = hamiltonian(x0), hamiltonian(x1)
    terms = grad * d
    excess = (h1 - h0)[:, None] - terms.sum(1, keepdim=True)
    with torch.no_grad():
        # the numerator's rounding: H's two values (a network's own sums round at a few ulps of |H|)
        # and the dot product's terms; its move of x1: over |d|^2, times |d|, times h ~ |d| / |grad H|
        eps = torch.finfo(excess.dtype).eps
        noise = eps * (2 * (h0.abs() + h1.abs())[:, None] + terms.abs().sum(1, keepdim=True))
        d_max, g_max = d.abs().amax(1, keepdim=True), grad.abs().amax(1, keepdim=True)
        moves = noise * d_max * d_max / (dd * g_max).clamp_min(torch.finfo(dd.dtype).tiny)
        short = (moves > default_tol(excess.dtype) * m.abs().amax(1, keepdim=True).clamp_min(1.0)) & (dd > 0)
    if in_model_axis() or bool(short.any()):      # under vmap over models no branch on values
        # Gauss-Legendre nodes 1/2 -+ sqrt(15)/10 beside the midpoint (weights 5/18, 8/18, 5/18):
        # the numerator is (5/18) (grad H(a) + grad H(b) - 2 grad H(m)) . d, differences of gradients
        offset = (0.15 ** 0.5) * d
        ends = gradient_of(hamiltonian, torch.cat([m - offset, m + offset]))
        curve = ends[:len(m)] + ends[len(m):] - 2 * grad
        excess = torch.where(short, (5 / 18) * (curve * d).sum(1, keepdim=True), excess)
    # grad-bar . d equals the numerator plus grad H(m) . d, whatever the rounding of the quotient; at d = 0 it is grad H
    return grad + torch.where(dd > 0, excess / dd.clamp_min(torch.finfo(dd.dtype).tiny), 0.0) * d


def structured(g: torch.Tensor, S: torch.Tensor | None) -> torch.Tensor:
    """``S g`` for gradients ``g`` ``(batch, dim)``; S None: the canonical [[0, I], [-I, 0]], (dH/dp, -dH/dq)."""
    if S is None:
        n = g.shape[1] // 2
        return torch.cat([g[:, n:], -g[:, :n]], 1)
    return g @ S.to(g).T


def energy_parts(f, dim: int, method: str = "discrete_gradient"):
    """``(discrete_gradient(x0, x1), S)`` of a field that carries its H (``hnn.interface.EnergyField``);
    ValueError naming the fix for one that does not."""
    hamiltonian = f.hamiltonian if isinstance(f, EnergyField) else None
    if hamiltonian is None:
        raise ValueError(f"{method} steps x1 = x0 + h S grad-bar H(x0, x1) and needs the field's H, but "
                         f"{getattr(f, '__qualname__', type(f).__name__)} carries none: roll out an hnn.Model that "
                         "declares conservative (hnn.rollout(model, ...)) or wrap a known system's field as "
                         "hnn.interface.EnergyField(f, hamiltonian)")
    if f.structure is None and dim % 2:
        raise ValueError(f"{method} needs x = [q, p] of even dimension for the canonical S, got dim={dim}")
    return (f.discrete_gradient or (lambda x0, x1: gonzalez(hamiltonian, x0, x1))), f.structure


class DiscreteGradient(ImplicitStepper):
    """x1 = x0 + h S grad-bar H(x0, x1) by fixed-point iteration to ``tol``, started from the last
    increment rescaled (explicit midpoint at first). Checks once that the field is S grad H."""

    name, equation = "discrete_gradient", "x1 = x0 + h S grad-bar H(x0, x1)"

    def __init__(self, f, dim: int, dtype: torch.dtype, tol: float | None = None, max_iter: int = 100,
                 **options):
        super().__init__(f, dim, dtype, tol, max_iter)
        self.dg, self.S = energy_parts(f, dim)
        self.last, self.checked = None, False

    def update(self, x: torch.Tensor, x1: torch.Tensor, h: float) -> torch.Tensor:
        """x0 + h S grad-bar H(x0, x1), ``(batch, dim)``."""
        return x + h * structured(self.dg(x, x1), self.S)

    def _check_structure(self, x: torch.Tensor) -> None:
        """The field must be S grad H (S grad-bar H(x, x)): else this method integrates another flow."""
        with torch.no_grad():
            field, ours = self.f(x), structured(self.dg(x, x), self.S)
        self.nfev += 1
        scale = 1 + field.abs().max()
        gap = float((field - ours).abs().max() / scale)
        if not gap <= 1e3 * torch.finfo(x.dtype).eps ** 0.5:
            raise ValueError(f"discrete_gradient: the field is not S grad H of the H it carries (relative gap "
                             f"{gap:.3g}): its model's time_derivative is not Hamilton's equations of its hamiltonian "
                             "(declare structure(), or use method='midpoint')")
        self.checked = True

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        if not self.checked:
            self._check_structure(x.detach())
        if self.last is None:
            x1 = x + h * self.f(x + 0.5 * h * self.f(x))      # explicit midpoint: O(h^3) off
            self.nfev += 2
        else:
            h_last, increment = self.last
            x1 = x + (h / h_last) * increment
        x1 = self.solve(x, x1, h)
        self.last = (h, (x1 - x).detach())
        return x1

    def reset(self, x: torch.Tensor) -> None:
        self.last = None
