"""The features interface: what a fit's feature set gives, so that a new one is one module and one row.

A feature set is a ``Features`` (an ``nn.Module``): ``width`` functions phi_k of inputs of width ``in_dim``,
with their values, their input gradients in closed form, their names, and how they are made for a run. A
fitted model (``hnn.fits.models``) combines them linearly, H = phi(x) . c or dx/dt = phi(x) C, and a fit
(``hnn.fits.fitting``) solves c by least squares; the row of ``hnn.fits.FITS`` names the feature sets it
uses and its solve (``hnn.fits.solves``). What a feature set declares:

- ``forms``: the inputs it can stand for, which the model kinds ask for (``'hamiltonian'``: H's terms of
  x = [q, p]; ``'field'``: dx/dt's terms of x; ``'kinetic'``/``'potential'``: T's of p, V's of q;
  ``'radial'``: V's of a pair distance r); ``make(spec, form, in_dim)``: the features of a run's
  ``hnn.specs.ModelSpec`` for one form (a ``classmethod``: the width, degree or terms it reads);
- ``forward(x)`` ``(rows, width)``, ``jacobian(x)`` ``(rows, width, in_dim)`` (the design of a fit of a
  gradient), ``gradient(x, coef)`` ``(rows, in_dim)`` (d/dx of phi(x) . coef; by default through the
  Jacobian), and, where the Jacobian factors through a few functions, ``gradient_factors()`` (the solve
  then never builds it; None: it does not);
- ``names(columns)``: each feature as text; ``formula``: whether those are formulas, so that a sparse sum
  of them prints as an equation (``hnn.fits.equations`` reads the library's terms);
- ``drawn``: whether its parameters are drawn from the data by the fit's sampler before the solve
  (``set(weight, bias)``; ``hnn.fits.sampling``), or fixed by ``make``;
- ``constant``: whether one of its functions is a constant (else a field model adds a bias of its own);
- ``subset``: whether ``forward(x, keep)`` evaluates only the terms ``keep`` (a sparse model's shortcut).

Parameters are frozen (``requires_grad=False``) parameters and buffers, so a fitted model saves and
reloads as any model does; float64. The shape learned from pysindy's ``BaseFeatureLibrary``: values,
derivatives and names of one set of functions, with the fitting kept outside.
"""
from __future__ import annotations

import torch
from torch import nn

FORMS = ("hamiltonian", "field", "kinetic", "potential", "radial")


class Features(nn.Module):
    """A feature set (see the module). Subclasses set ``width`` and ``in_dim`` and define ``forward`` and
    ``jacobian`` (``gradient`` follows from it), ``names`` and ``make``; the class attributes say the rest."""
    forms: tuple[str, ...] = FORMS
    formula = False
    drawn = False
    constant = False
    subset = False
    width: int
    in_dim: int

    @classmethod
    def make(cls, spec, form: str, in_dim: int) -> Features:
        """The features of ``spec`` (an ``hnn.specs.ModelSpec``) standing for ``form`` on ``in_dim`` inputs."""
        raise NotImplementedError(f"{cls.__name__} does not say how it is made for a run: define make()")

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """phi ``(rows, width)`` at ``x`` ``(rows, in_dim)``."""
        raise NotImplementedError

    def jacobian(self, x: torch.Tensor) -> torch.Tensor:
        """d phi_k / d x_j ``(rows, width, in_dim)``."""
        raise NotImplementedError

    def gradient(self, x: torch.Tensor, coef: torch.Tensor) -> torch.Tensor:
        """d/dx of phi(x) . coef ``(rows, in_dim)`` (``coef`` ``(width,)``)."""
        return torch.einsum("rki,k->ri", self.jacobian(x), coef)

    def gradient_factors(self):
        """None, or ``(basis, V)`` with d phi_k / d x_i = basis(x)[:, m] V[m, k, i] (``V`` ``(M, width, in_dim)``)
        or, for ``V`` ``(width, in_dim)``, basis(x)[:, k] V[k, i]: a fit of the gradients then factors its
        design through ``basis`` (``hnn.fits.fitting``). None by default: the design is the Jacobian."""
        return None

    def set(self, weight, bias) -> None:
        """Set drawn parameters (a ``drawn`` set's; the sampler's ``(weight, bias)``)."""
        raise TypeError(f"{type(self).__name__} is fixed by make(), not drawn from the data")

    def names(self, columns: list[str]) -> list[str]:
        """Each feature as text over the input ``columns``' names."""
        return [f"phi{k}" for k in range(self.width)]

    def describe(self, column: str) -> str:
        """One feature's shape as text on input ``column`` (``'tanh(w r + b)'``): what a model of features with no
        formula says of them."""
        return f"phi({column})"


def made(feature_sets: tuple, spec, form: str, in_dim: int) -> Features:
    """The features of the first of ``feature_sets`` (``Features`` classes: a fit row's) that stands for
    ``form``, made for ``spec``; a ValueError naming the fit, the form and the kind where none does."""
    if form not in FORMS:
        raise ValueError(f"unknown features form {form!r}; the forms are {', '.join(FORMS)}")
    for features in feature_sets:
        if form in features.forms:
            return features.make(spec, form, in_dim)
    offered = sorted({f for features in feature_sets for f in features.forms})
    raise ValueError(f"fit {spec.fit!r} has no features for the {form} terms the {spec.kind} kind reads (its "
                     f"{', '.join(f.__name__ for f in feature_sets)} stand for {', '.join(offered)}): pick "
                     "another fit or kind")
