"""Learned symplectic maps: the state ``x = [q, p]`` ``(batch, 2n)`` one data step ``dt`` later, one
forward pass a step, symplectic by construction (no field, no integrator).

- ``LASympNet`` (Jin et al. 2020): linear modules (``LinearShears``: alternating shears by symmetric
  n x n matrices, then a shift) between activation shears (``ActivationShear``).
- ``GSympNet`` (Jin et al. 2020): gradient shears (``GradientShear``), p <- p + grad V(q), then
  q <- q + grad T(p), alternately.
- ``HenonNet`` (Burby, Tang & Qin 2020): Henon layers (``HenonLayer``), each the fourth power of one
  Henon map (q, p) -> (p + eta, -q + grad V(p)), which is the identity for V = 0, eta = 0.

Why each layer is symplectic (D^T J D = J for its Jacobian D, J = [[0, I], [-I, 0]]): a shear moves
one half by the gradient of a scalar function of the other half, D = [[I, A], [0, I]] with A the
symmetric Hessian; a Henon map has D = [[0, I], [-I, A]]; a shift has D = I; compositions of
symplectic maps are symplectic. Each layer has an exact inverse (``inverse``), so a map runs
backwards too. Every potential is V(y) = sum_j a_j S(K y + b)_j with S' the activation, so its
gradient K^T (a * act(K y + b)) costs two matrix products and no derivative of the activation.

The weights start near zero (N(0, 0.01^2), as jpzxshi/sympnets' modules), so a map starts near the
identity. The classes' defaults are the commands' (``hnn.settings.RunSettings``: tanh, ``--hidden_dim`` 200 terms,
``--map_layers`` 4), so a map built in Python is the one ``--model g_sympnet`` trains: SympNets' sigmoid
left the pendulum's map near the identity in p (docs/maps.md, "Train a map on your own pairs"). The step ``dt`` is the data's time step, an attribute given at construction (a run's
``ModelSpec.dt``, recorded in its args.json): ``hnn.rollout`` steps the map on ``t_eval`` of
multiples of it and refuses any other. Plain tensor operations only: groups of maps train under
``torch.func.vmap`` (``hnn.trainers.vmap``).
"""
from __future__ import annotations

import math

import numpy as np
import torch
from scipy.special import expit
from torch import nn

from ..interface import Model
from ..modes import frozen_kernels, in_model_axis
from ..settings import RunSettings
from .mlp import get_nonlinearity
from .tanh_mlp import KERNEL_MAX_ROWS

INIT_STD = 0.01         # the scale of the weights at the start: each layer is near the identity
# the activations whose numpy twin serves a rollout's few states (``MapKernel``); others keep the torch path
_NUMPY_ACTIVATIONS = {"tanh": np.tanh, "sigmoid": expit}


# their in-place forms, for a pass without a graph (an activation of 1000 x 50 in place: 31 us against 52)
_IN_PLACE = {"tanh": torch.Tensor.tanh_, "sigmoid": torch.Tensor.sigmoid_}


def _activation(name: str):
    """torch's own tanh and sigmoid (the MLPs' tanh splits into four passes that pay off inside an HNN's
    double backward only; here one pass is cheaper), any other of ``hnn.names.NONLINEARITIES`` as the MLPs'."""
    return {"tanh": torch.tanh, "sigmoid": torch.sigmoid}.get(name) or get_nonlinearity(name)


def _small(*shape: int) -> nn.Parameter:
    return nn.Parameter(torch.randn(*shape) * INIT_STD)


class PotentialGradient(nn.Module):
    """``grad V(y)`` of V(y) = sum_j a_j S(K y + b)_j, S' = ``activation``, for ``y`` ``(batch, n)``:
    K^T (a * act(K y + b)), K ``(width, n)``, a and b ``(width,)``."""

    def __init__(self, n: int, width: int, activation: str):
        super().__init__()
        self.activation, self._act = activation, _activation(activation)
        self._act_in_place = _IN_PLACE.get(activation)
        self.K, self.a, self.b = _small(width, n), _small(width), nn.Parameter(torch.zeros(width))

    def add_to(self, z: torch.Tensor, y: torch.Tensor, sign: float = 1.0) -> torch.Tensor:
        """``z + sign * grad V(y)``, both ``(batch, n)``: two fused products (the activation in place on
        the first one's fresh result where no graph is kept: a rollout's many states)."""
        h = torch.addmm(self.b, y, self.K.t())
        h = self._act_in_place(h) if self._act_in_place and not torch.is_grad_enabled() else self._act(h)
        return torch.addmm(z, h, self.a[:, None] * self.K, alpha=sign)

    def numpy_add_to(self):
        """``add_to`` (sign +1) in numpy on a copy of the weights now: ``(z, y) -> z + grad V(y)``."""
        act, Kt, b = _NUMPY_ACTIVATIONS[self.activation], _array(self.K.t()), _array(self.b)
        aK = _array(self.a[:, None] * self.K)

        def add_to(z: np.ndarray, y: np.ndarray) -> np.ndarray:
            h = y @ Kt
            h += b
            return z + act(h, out=h) @ aK
        return add_to


class Shear(nn.Module):
    """Moves one half of the state by a gradient of the other: ``part='p'``: p <- p + grad V(q);
    ``part='q'``: q <- q + grad T(p). A subclass gives ``increment(z, y, sign)`` = z + sign * grad(y)."""

    def __init__(self, part: str):
        super().__init__()
        if part not in ("q", "p"):
            raise ValueError(f"a shear moves the 'q' or the 'p' half, got {part!r}")
        self.part = part

    def increment(self, z: torch.Tensor, y: torch.Tensor, sign: float) -> torch.Tensor:
        raise NotImplementedError

    def forward(self, q: torch.Tensor, p: torch.Tensor, sign: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
        if self.part == "p":
            return q, self.increment(p, q, sign)
        return self.increment(q, p, sign), p

    def inverse(self, q: torch.Tensor, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self(q, p, -1.0)     # the moved half goes back by the same gradient of the unmoved one

    def numpy_increment(self):
        """``increment`` (sign +1) in numpy on a copy of the weights now: ``(z, y) -> z + grad(y)``."""
        raise NotImplementedError

    def numpy_forward(self):
        """``forward`` in numpy on a copy of the weights now: ``(q, p) -> (q, p)``."""
        increment = self.numpy_increment()
        if self.part == "p":
            return lambda q, p: (q, increment(p, q))
        return lambda q, p: (increment(q, p), p)


class GradientShear(Shear):
    """A G-SympNet module: the shear by ``PotentialGradient``, ``width`` terms."""

    def __init__(self, n: int, width: int, part: str, activation: str = RunSettings.nonlinearity):
        super().__init__(part)
        self.potential = PotentialGradient(n, width, activation)

    def increment(self, z, y, sign):
        return self.potential.add_to(z, y, sign)

    def numpy_increment(self):
        return self.potential.numpy_add_to()


class ActivationShear(Shear):
    """An LA-SympNet activation module: the shear z <- z + a * act(y), ``a`` ``(n,)`` (the gradient
    of sum_i a_i S(y_i))."""

    def __init__(self, n: int, part: str, activation: str = RunSettings.nonlinearity):
        super().__init__(part)
        self.activation, self._act = activation, _activation(activation)
        self.a = _small(n)

    def increment(self, z, y, sign):
        return torch.addcmul(z, self._act(y), self.a, value=sign)

    def numpy_increment(self):
        act, a = _NUMPY_ACTIVATIONS[self.activation], _array(self.a)
        return lambda z, y: z + a * act(y)


class LinearShears(nn.Module):
    """An LA-SympNet linear module: ``sublayers`` shears by symmetric matrices S_k = A_k + A_k^T,
    alternately p <- p + q S_k and q <- q + p S_k (starting with ``first``), then the shift
    q <- q + b_q, p <- p + b_p."""

    def __init__(self, n: int, sublayers: int, first: str = "p"):
        super().__init__()
        if first not in ("q", "p"):
            raise ValueError(f"a linear module starts with the 'q' or the 'p' half, got {first!r}")
        self.first = first
        self.A = nn.ParameterList([_small(n, n) for _ in range(sublayers)])
        self.b_q, self.b_p = nn.Parameter(torch.zeros(n)), nn.Parameter(torch.zeros(n))

    def _moves_p(self, k: int) -> bool:
        return (k % 2 == 0) == (self.first == "p")

    def forward(self, q: torch.Tensor, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        for k, A in enumerate(self.A):
            S = A + A.t()
            if self._moves_p(k):
                p = torch.addmm(p, q, S)
            else:
                q = torch.addmm(q, p, S)
        return q + self.b_q, p + self.b_p

    def numpy_forward(self):
        """``forward`` in numpy on a copy of the weights now."""
        shears = [(self._moves_p(k), _array(A + A.t())) for k, A in enumerate(self.A)]
        b_q, b_p = _array(self.b_q), _array(self.b_p)

        def forward(q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            for moves_p, S in shears:
                if moves_p:
                    p = p + q @ S
                else:
                    q = q + p @ S
            return q + b_q, p + b_p
        return forward

    def inverse(self, q: torch.Tensor, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        q, p = q - self.b_q, p - self.b_p
        for k in reversed(range(len(self.A))):
            S = self.A[k] + self.A[k].t()
            if self._moves_p(k):
                p = torch.addmm(p, q, S, alpha=-1.0)
            else:
                q = torch.addmm(q, p, S, alpha=-1.0)
        return q, p


class HenonLayer(nn.Module):
    """A HenonNet layer: four times the Henon map (q, p) -> (p + eta, -q + grad V(p)) of one
    potential V (``PotentialGradient``, ``width`` terms) and one shift ``eta`` ``(n,)``."""

    def __init__(self, n: int, width: int, activation: str = RunSettings.nonlinearity):
        super().__init__()
        self.potential = PotentialGradient(n, width, activation)
        self.eta = nn.Parameter(torch.zeros(n))

    def forward(self, q: torch.Tensor, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        for _ in range(4):
            q, p = p + self.eta, self.potential.add_to(-q, p)
        return q, p

    def numpy_forward(self):
        """``forward`` in numpy on a copy of the weights now."""
        add_to, eta = self.potential.numpy_add_to(), _array(self.eta)

        def forward(q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            for _ in range(4):
                q, p = p + eta, add_to(-q, p)
            return q, p
        return forward

    def inverse(self, q: torch.Tensor, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        for _ in range(4):
            before = q - self.eta           # the p before the map, whose potential gradient gave this p
            q, p = self.potential.add_to(-p, before), before
        return q, p


class SymplecticMap(Model):
    """A learned map of ``x = [q, p]`` ``(batch, input_dim)`` to its state ``dt`` later: the
    composition of ``layers`` (each a symplectic map of ``(q, p)`` halves with an exact inverse).
    ``dt``: the step (the data's); None until given (``hnn.rollout`` refuses a map without one)."""
    steps = True

    def __init__(self, input_dim: int, layers: list[nn.Module], dt: float | None = None):
        super().__init__()
        if input_dim % 2 or input_dim < 2:
            raise ValueError(f"a symplectic map needs an even input_dim (x = [q, p]), got {input_dim}")
        self.input_dim, self.n = input_dim, input_dim // 2
        self.layers = nn.ModuleList(layers)
        self.dt = check_step(dt)

    def _halves(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if x.dim() != 2 or x.shape[1] != self.input_dim:
            raise ValueError(f"expected x of shape (batch, {self.input_dim}), got {tuple(x.shape)}")
        return x[:, :self.n], x[:, self.n:]

    def step(self, x: torch.Tensor) -> torch.Tensor:
        """The states ``dt`` after ``x``, ``(batch, input_dim)``: one pass through the layers (in numpy on
        weights taken once for a rollout's few states: ``MapKernel``)."""
        kernel = self._kernel(x)
        if kernel is not None:
            return kernel(x)
        q, p = self._halves(x)
        for layer in self.layers:
            q, p = layer(q, p)
        return torch.cat([q, p], dim=1)

    def inverse(self, x: torch.Tensor) -> torch.Tensor:
        """The states ``dt`` before ``x`` (``step``'s exact inverse), ``(batch, input_dim)``."""
        q, p = self._halves(x)
        for layer in reversed(self.layers):
            q, p = layer.inverse(q, p)
        return torch.cat([q, p], dim=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.step(x)

    def _kernel(self, x: torch.Tensor):
        """The ``MapKernel`` of this map inside ``frozen_weights`` (a rollout) for ``x`` of at most
        ``KERNEL_MAX_ROWS`` CPU rows in the weights' dtype, without grad; else None (the torch path)."""
        kernels = frozen_kernels()
        if (kernels is None or torch.is_grad_enabled() or in_model_axis() or len(x) > KERNEL_MAX_ROWS
                or not x.is_cpu or x.dim() != 2 or x.shape[1] != self.input_dim):
            return None
        entry = kernels.get((id(self), "map"))
        if entry is None or entry[0] is not self:      # the owner is held, so its id is not reused meanwhile
            entry = kernels[(id(self), "map")] = (self, MapKernel(self) if self._numpy_applies() else None)
        kernel = entry[1]
        return kernel if kernel is not None and x.dtype is kernel.dtype else None

    def _numpy_applies(self) -> bool:
        return all(m.activation in _NUMPY_ACTIVATIONS for m in self.modules()
                   if isinstance(m, (PotentialGradient, ActivationShear)))

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        raise TypeError(f"{type(self).__name__} is a learned map with no field dx/dt: it steps x -> x(t + dt) "
                        "itself; roll it out with hnn.rollout(model, x0, t_eval) on t_eval of multiples of its dt")

    def extra_repr(self) -> str:
        return f"input_dim={self.input_dim}, dt={self.dt}"


def _array(t: torch.Tensor) -> np.ndarray:
    """A contiguous numpy copy of ``t`` (CPU, no grad)."""
    return np.ascontiguousarray(t.detach().cpu().numpy().copy())


class MapKernel:
    """A map's ``step`` in numpy on weights taken once, for a rollout's few states: each layer's
    ``numpy_forward`` in turn, the halves kept apart between layers. ``kernel(x)`` maps ``(batch,
    input_dim)`` CPU states of the weights' dtype to a new tensor. It holds copies of the weights, so
    it serves only inside ``frozen_weights`` (a rollout), where they cannot change (as
    ``hnn.models.tanh_mlp.EvaluationKernel``)."""

    def __init__(self, model: SymplecticMap):
        with torch.no_grad():
            self.dtype, self.n = next(model.parameters()).dtype, model.n
            self.layers = [layer.numpy_forward() for layer in model.layers]

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        z = x.numpy()
        q, p = z[:, :self.n], z[:, self.n:]
        for layer in self.layers:
            q, p = layer(q, p)
        return torch.from_numpy(np.concatenate([q, p], axis=1))


def check_step(dt) -> float | None:
    """``dt`` as a float, None kept; a ValueError for a step that is not positive and finite."""
    if dt is None:
        return None
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"a map's step dt must be a positive finite time, got {dt!r}")
    return float(dt)


def _parts(count: int) -> list[str]:
    return ["p" if k % 2 == 0 else "q" for k in range(count)]


class GSympNet(SymplecticMap):
    """G-SympNet (Jin et al. 2020): ``layers`` gradient shears of ``width`` terms, moving p then q alternately."""

    def __init__(self, input_dim: int, width: int = RunSettings.hidden_dim, layers: int = RunSettings.map_layers,
                 activation: str = RunSettings.nonlinearity, dt: float | None = None):
        n = input_dim // 2
        super().__init__(input_dim, [GradientShear(n, width, part, activation) for part in _parts(layers)], dt)


class LASympNet(SymplecticMap):
    """LA-SympNet (Jin et al. 2020): ``layers`` linear modules of ``sublayers`` shears each, with an
    activation shear between two consecutive ones (``layers - 1``), the halves alternating."""

    def __init__(self, input_dim: int, layers: int = RunSettings.map_layers, sublayers: int = 2,
                 activation: str = RunSettings.nonlinearity, dt: float | None = None):
        n = input_dim // 2
        parts = _parts(layers)
        modules: list[nn.Module] = []
        for k, part in enumerate(parts):
            modules.append(LinearShears(n, sublayers, part))
            if k < layers - 1:
                modules.append(ActivationShear(n, part, activation))
        super().__init__(input_dim, modules, dt)


class HenonNet(SymplecticMap):
    """HenonNet (Burby, Tang & Qin 2020): ``layers`` Henon layers, each potential of ``width`` terms."""

    def __init__(self, input_dim: int, width: int = RunSettings.hidden_dim, layers: int = RunSettings.map_layers,
                 activation: str = RunSettings.nonlinearity, dt: float | None = None):
        super().__init__(input_dim, [HenonLayer(input_dim // 2, width, activation) for _ in range(layers)], dt)


__all__ = ["ActivationShear", "GSympNet", "GradientShear", "HenonLayer", "HenonNet", "LASympNet", "LinearShears",
           "MapKernel", "PotentialGradient", "SymplecticMap", "check_step"]
