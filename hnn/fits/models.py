"""The models a linear fit makes: a sum of features (``hnn.fits.features``) whose last weights one
least-squares solve finds, as an ``hnn.Model`` of one of the kinds whose field is linear in them.

- ``FittedHNN`` (kind ``hnn``): H(x) = phi(x) . c + c0, dx/dt = J grad H. J grad H is linear in c, so
  the fit of dx/dt is one least-squares problem; c0 (no gradient sees it) is fixed by one known H value.
- ``FittedSeparable`` (kind ``separable``): H = T(p) + V(q), T = phi_T(p) . a, V = phi_V(q) . b; dq/dt = dT/dp
  fits a and dp/dt = -dV/dq fits b, two problems.
- ``FittedField`` (kind ``baseline``, and SINDy): dx/dt = phi(x) C (+ a bias row for sampled neurons); no H.

Each answers through the model interface (``time_derivative``, ``hamiltonian`` where conservative, the
separable halves) and lists its least-squares problems (``parts``): the design rows ``(A, Y)`` of a chunk
of data and where the solution goes. States ``x = [q, p]`` ``(rows, 2n)``, float64.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import nn

from ..interface import ANY_STATE, UNIT_MASS, Model
from .base import Features
from .equations import Frame, terms, written
from .features import Library


def _frozen(*shape) -> nn.Parameter:
    return nn.Parameter(torch.zeros(*shape, dtype=torch.float64), requires_grad=False)


@dataclass
class Part:
    """One least-squares problem of a fitted model: ``features`` reading ``inputs(x)`` of the states (None: the
    columns are no feature set's, as a pair model's inverse masses);
    ``design(x, y, weights)``, the rows ``(A (rows, columns), Y (rows, rhs))`` of a chunk of states ``x`` and
    their ``y`` = dx/dt (``weights`` ``(dim,)`` or None: each component's weight in the loss);
    ``assign(coef (columns, rhs))`` puts the solution in place; ``supervised``: the sampler may draw
    this layer's neurons where ``y`` changes fastest (SWIM with function values); ``factored()``, where the
    design is the features' gradient: ``(basis, V, targets)``, the rows of component ``targets[j]`` being
    ``basis(x) * V[:, j]`` (a sampled layer: its slopes, ``V`` ``(K, m)``) or ``basis(x) @ V[:, :, j]`` (a
    library: the functions its derivatives are made of, ``V`` ``(M, K, m)``; ``gradient_factors()`` of
    ``hnn.fits.features``); ``hnn.fits.fitting`` solves it without building the rows."""
    features: Features | None
    inputs: Callable
    design: Callable
    assign: Callable
    columns: int
    rhs: int = 1
    supervised: bool = False
    name: str = "H"
    factored: Callable | None = None


def _weighted(A: torch.Tensor, Y: torch.Tensor, weights, rows_per_state: int, components) -> tuple:
    """``(A, Y)`` of rows ordered (state, component) with each row times sqrt(weight of its component)."""
    if weights is None:
        return A, Y
    w = torch.as_tensor(weights, dtype=A.dtype)[list(components)].sqrt().repeat(len(A) // rows_per_state)[:, None]
    return A * w, Y * w


def _state_width(spec, even: bool = True) -> int:
    """``spec.input_dim``, or a ValueError where it is no state x = [q, p] (of even width where ``even``)."""
    dim = spec.input_dim
    if not isinstance(dim, int) or dim < 2 or (even and dim % 2):
        raise ValueError(f"--fit {spec.fit} needs the state's width x = [q, p], got input_dim={dim!r}")
    return dim


class FittedHNN(Model):
    """H(x) = phi(x) . coef + offset over ``features`` (sampled neurons or a library of H's terms)."""
    reads_bodies = False        # the fitted models' declaration: x read as it is (the pair model reads bodies)
    conservative = True
    takes = UNIT_MASS
    kind = "hnn"

    @classmethod
    def from_spec(cls, spec, features: Callable) -> FittedHNN:
        """The untrained model of ``spec`` over ``features('hamiltonian', width)`` (the fit row's, made)."""
        dim = _state_width(spec)
        return cls(dim, features("hamiltonian", dim))

    def __init__(self, input_dim: int, features: Features):
        super().__init__()
        if input_dim % 2:
            raise ValueError(f"a fitted HNN reads x = [q, p] of even width, got {input_dim}")
        self.input_dim, self.n = input_dim, input_dim // 2
        self.features = features
        self.coef, self.offset = _frozen(features.width), _frozen(())

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H ``(rows,)``."""
        return self.features(x) @ self.coef + self.offset

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        g = self.features.gradient(x, self.coef)
        return torch.cat([g[:, self.n:], -g[:, :self.n]], dim=1)

    def _design(self, x, y, weights):
        jac = self.features.jacobian(x)                                    # (rows, K, 2n): grad of each feature
        field = torch.cat([jac[:, :, self.n:], -jac[:, :, :self.n]], dim=2)  # J grad, per feature
        A = field.permute(0, 2, 1).reshape(-1, self.features.width)
        return _weighted(A, y.reshape(-1, 1), weights, self.input_dim, range(self.input_dim))

    def _assign(self, coef):
        with torch.no_grad():
            self.coef.copy_(coef[:, 0])

    def _factored(self):
        factors = self.features.gradient_factors()
        if factors is None:
            return None
        basis, G = factors
        # d/dt of component j is (J grad H)_j: the gradient's factors with J applied on their last axis
        return basis, torch.cat([G[..., self.n:], -G[..., :self.n]], dim=-1), list(range(self.input_dim))

    def parts(self) -> list[Part]:
        return [Part(self.features, lambda x: x, self._design, self._assign, self.features.width, supervised=True,
                     factored=self._factored)]

    def anchor(self, x0: torch.Tensor, H0) -> None:
        """Fix the constant so that H(x0) = H0 (``x0`` ``(1, 2n)``): the one value dx/dt cannot give."""
        with torch.no_grad():
            self.offset.copy_(torch.as_tensor(H0, dtype=torch.float64).reshape(())
                              - (self.features(x0) @ self.coef).reshape(()))

    def equation(self, digits: int = 4, frame: Frame | None = None) -> str:
        """``'H = q^2 + p^2'``: the nonzero terms of a library fit and its constant, in ``frame``
        (``hnn.fits.equations.Frame``: the user's columns and units; default the model's own q and p)."""
        frame = frame or Frame.own(self.input_dim)
        constant, pairs = terms(_library(self.features), self.coef, frame, frame.energy, digits, float(self.offset))
        return "H = " + written(constant, pairs, digits)


class FittedSeparable(Model):
    """H = T(p) + V(q): ``kinetic`` features of p, ``potential`` features of q, each with its coefficients."""
    conservative = True
    separable = True
    takes = UNIT_MASS
    kind = "separable"
    reads_bodies = False

    @classmethod
    def from_spec(cls, spec, features: Callable) -> FittedSeparable:
        """The untrained model of ``spec`` over ``features('kinetic', n)`` and ``features('potential', n)``."""
        dim = _state_width(spec)
        return cls(dim, features("kinetic", dim // 2), features("potential", dim // 2))

    def __init__(self, input_dim: int, kinetic: Features, potential: Features):
        super().__init__()
        if input_dim % 2:
            raise ValueError(f"a fitted separable HNN reads x = [q, p] of even width, got {input_dim}")
        self.input_dim, self.n = input_dim, input_dim // 2
        self.kinetic_features, self.potential_features = kinetic, potential
        self.kinetic_coef, self.potential_coef = _frozen(kinetic.width), _frozen(potential.width)
        self.offset = _frozen(())

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        q, p = x[:, :self.n], x[:, self.n:]
        return self.kinetic_features(p) @ self.kinetic_coef + self.potential_features(q) @ self.potential_coef \
            + self.offset

    def kinetic_gradient(self, p: torch.Tensor) -> torch.Tensor:
        """dT/dp ``(rows, n)``."""
        return self.kinetic_features.gradient(p, self.kinetic_coef)

    def potential_gradient(self, q: torch.Tensor) -> torch.Tensor:
        """dV/dq ``(rows, n)``."""
        return self.potential_features.gradient(q, self.potential_coef)

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        return torch.cat([self.kinetic_gradient(x[:, self.n:]), -self.potential_gradient(x[:, :self.n])], dim=1)

    def _part(self, kinetic: bool) -> Part:
        features = self.kinetic_features if kinetic else self.potential_features
        coef = self.kinetic_coef if kinetic else self.potential_coef
        # dq/dt = dT/dp reads T on p; dp/dt = -dV/dq reads V on q
        half, rows, sign = ((slice(self.n, None), range(self.n), 1.0) if kinetic
                            else (slice(None, self.n), range(self.n, self.input_dim), -1.0))

        def design(x, y, weights):
            A = sign * features.jacobian(x[:, half]).permute(0, 2, 1).reshape(-1, features.width)
            return _weighted(A, y[:, list(rows)].reshape(-1, 1), weights, self.n, rows)

        def assign(solution):
            with torch.no_grad():
                coef.copy_(solution[:, 0])

        def factored():
            factors = features.gradient_factors()
            if factors is None:
                return None
            basis, G = factors
            return (lambda x: basis(x[:, half])), sign * G, list(rows)

        return Part(features, lambda x: x[:, half], design, assign, features.width, name="T" if kinetic else "V",
                    factored=factored)

    def parts(self) -> list[Part]:
        return [self._part(True), self._part(False)]

    def anchor(self, x0: torch.Tensor, H0) -> None:
        """Fix the constant so that H(x0) = H0."""
        with torch.no_grad():
            self.offset.copy_(torch.as_tensor(H0, dtype=torch.float64).reshape(()) - (self.hamiltonian(x0).reshape(())
                                                                                     - self.offset))

    def equation(self, digits: int = 4, frame: Frame | None = None) -> str:
        """``'H = 3 - 3 cos(q) + p^2'``: V's terms, then T's, in ``frame`` (as ``FittedHNN.equation``)."""
        frame = frame or Frame.own(self.input_dim)
        energy, n = frame.energy, self.n
        v0, potential = terms(_library(self.potential_features), self.potential_coef, frame.columns(slice(None, n)),
                              energy, digits)
        t0, kinetic = terms(_library(self.kinetic_features), self.kinetic_coef, frame.columns(slice(n, None)),
                            energy, digits)
        return "H = " + written(v0 + t0 + energy * float(self.offset), potential + kinetic, digits)


class FittedField(Model):
    """dx/dt = phi(x) coef + bias: a field with no H (the baseline's, SINDy's)."""
    takes = ANY_STATE
    kind = "baseline"
    reads_bodies = False

    @classmethod
    def from_spec(cls, spec, features: Callable) -> FittedField:
        """The untrained model of ``spec`` over ``features('field', width)``."""
        dim = _state_width(spec, even=False)
        return cls(dim, features("field", dim))

    def __init__(self, input_dim: int, features: Features):
        super().__init__()
        self.input_dim = input_dim
        self.features = features
        # features with no constant among them (sampled neurons) get a bias row of their own; a library's
        # constant term is one of its terms
        self.has_bias = not features.constant
        self.coef, self.bias = _frozen(features.width, input_dim), _frozen(input_dim)

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        if self.features.subset:      # only the terms some component uses
            keep = (self.coef != 0).any(dim=1)
            return self.features(x, keep) @ self.coef[keep] + self.bias
        return self.features(x) @ self.coef + self.bias

    def _design(self, x, y, weights):
        # a library's values built on the transposed layout (its bits are forward's): the column-major (rows, terms)
        # the QR reads, at a fraction of forward's gathers and trig factors
        phi = self.features.transposed(x).T if isinstance(self.features, Library) else self.features(x)
        if self.has_bias:
            phi = torch.cat([phi, torch.ones_like(phi[:, :1])], dim=1)
        return phi, y     # the components are separate problems of one design: their weights change nothing

    def _assign(self, solution):
        with torch.no_grad():
            self.coef.copy_(solution[:self.features.width])
            if self.has_bias:
                self.bias.copy_(solution[-1])

    def parts(self) -> list[Part]:
        return [Part(self.features, lambda x: x, self._design, self._assign, self.features.width + self.has_bias,
                     rhs=self.input_dim, supervised=True, name="dx/dt")]

    def equation(self, digits: int = 4, frame: Frame | None = None) -> str:
        """One line per component, ``'dq/dt = 2 p'``, in ``frame`` (as ``FittedHNN.equation``): d x_j / dt =
        scale_j / time * f'_j(x')."""
        frame = frame or Frame.own(self.input_dim)
        lines = []
        for j, name in enumerate(frame.names):
            rate = frame.scale[j] / frame.time
            constant, pairs = terms(_library(self.features), self.coef[:, j], frame, rate, digits, float(self.bias[j]))
            lines.append(f"d{name}/dt = " + written(constant, pairs, digits))
        return "; ".join(lines)


def _library(features: Features) -> Library:
    """A fit's features if they are formulas (a library's written-out terms, which ``hnn.fits.equations``
    expands), else a ValueError (sampled neurons have no formula)."""
    if not features.formula:
        raise ValueError(f"a fit over {type(features).__name__} has no equation: only a library's terms print as one "
                         "(fit='library' or 'sindy')")
    return features
