"""The Hamiltonian Neural Network (Greydanus et al. 2019) on the paper's MLP, and the paper's baseline.

State convention: ``x = [q, p]`` of shape ``(batch, 2n)``; the first half is the
position half, the second half the momentum half.
"""
from __future__ import annotations

import warnings

import numpy as np
import torch
from torch import nn

from ..interface import ANY_STATE, UNIT_MASS, Model
from ..names import FIELD_TYPES
from ..settings import RunSettings
from . import tanh_mlp
from .mlp import MLP, PIECEWISE_LINEAR, input_gradient

# the outputs (F1, F2) each field type reads, in hnn.names.FIELD_TYPES' order (solenoidal, conservative, both)
FIELD_ROWS = dict(zip(FIELD_TYPES, ((1,), (0,), (0, 1)), strict=True))


def permutation_tensor(n: int, device: torch.device | str | None = None) -> torch.Tensor:
    """The ``(n, n)`` matrix M = [[0, I], [-I, 0]] of Hamilton's equations, ``dx/dt = grad H @ M.T``, on
    ``device`` (default: torch's default device, where a model's parameters are made)."""
    eye = torch.eye(n, device=device)
    return torch.cat([eye[n // 2:], -eye[: n // 2]])


class HNN(Model):
    """Hamiltonian Neural Network (Greydanus et al. 2019).

    ``differentiable_model`` maps ``(batch, input_dim)`` to two scalar fields ``(F1, F2)``
    (shape ``(batch, 2)``), or, with ``baseline=True``, directly to ``dx/dt`` of shape
    ``(batch, input_dim)`` (then the instance declares ``conservative=False``, as ``hnn.models.Baseline``).
    ``time_derivative`` builds the vector field from the autograd gradient: the solenoidal part
    ``grad F2 @ M.T`` (Hamilton's equations with H = F2), the conservative part ``grad F1``, or both.
    """
    conservative = True
    takes = UNIT_MASS

    def __init__(self, input_dim: int, differentiable_model: nn.Module, field_type: str = RunSettings.field_type,
                 baseline: bool = False):
        super().__init__()
        if field_type not in FIELD_TYPES:
            raise ValueError(f"unknown field_type {field_type!r}; choose one of {FIELD_TYPES}")
        if not baseline and input_dim % 2:
            raise ValueError(f"an HNN needs an even input_dim (x = [q, p]), got {input_dim}")
        out_dim = getattr(differentiable_model, "output_dim", None)
        wanted = input_dim if baseline else 2
        if out_dim is not None and out_dim != wanted:
            raise ValueError(f"{'a baseline' if baseline else 'an HNN'}'s network must output {wanted} values "
                             f"({'dx/dt' if baseline else 'F1, F2'}), but it outputs {out_dim}")
        if not baseline and getattr(differentiable_model, "nonlinearity_name", None) in PIECEWISE_LINEAR:
            warnings.warn(
                f"HNN with nonlinearity {differentiable_model.nonlinearity_name!r}: its second derivative "
                "vanishes almost everywhere, so the learned field is piecewise constant; use tanh "
                "(the paper's choice) or another smooth activation", stacklevel=2)
        self.input_dim = input_dim
        self.baseline = baseline
        if baseline:
            self.conservative, self.takes = False, ANY_STATE
        self.field_type = field_type
        self.differentiable_model = differentiable_model
        self.register_buffer("M", permutation_tensor(input_dim), persistent=False)

    def _check_input(self, x: torch.Tensor) -> None:
        if x.dim() != 2 or x.shape[1] != self.input_dim:
            raise ValueError(
                f"expected x of shape (batch, {self.input_dim}), got {tuple(x.shape)}; "
                "pass a batch of states, e.g. x.reshape(-1, input_dim)")

    def forward(self, x: torch.Tensor):
        """``(F1, F2)``, each ``(batch, 1)``; with ``baseline=True`` the network output ``(batch, input_dim)``."""
        self._check_input(x)
        y = self.differentiable_model(x)
        if self.baseline:
            return y
        if y.dim() != 2 or y.shape[1] != 2:
            raise ValueError(f"an HNN's network must output (batch, 2) = (F1, F2), got {tuple(y.shape)}")
        return y[:, :1], y[:, 1:]

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """The learned H = F2 at ``x``, shape ``(batch,)``."""
        if self.baseline:
            raise ValueError("a baseline model has no Hamiltonian; build it with baseline=False")
        return self.forward(x)[1].squeeze(1)

    def exact_discrete_gradient(self):
        """DGNet's discrete gradient of the paper's tanh MLP (``hnn.models.tanh_mlp.discrete_gradient``), else None."""
        net = self.differentiable_model
        if self.baseline or self.field_type != "solenoidal" or not (isinstance(net, MLP) and net._closed_form_applies()):
            return None
        return lambda x0, x1: tanh_mlp.discrete_gradient(x0, x1, *tanh_mlp.mlp_weights(net)[:4], net.linear3.weight[1])

    def time_derivative(self, x: torch.Tensor, t=None):
        """``dx/dt`` at ``x``, shape ``(batch, input_dim)``.

        The input gradient is autograd's (in closed form for the paper's tanh MLP, checked
        against autograd in the tests). Works with or without ``x.requires_grad`` and inside
        ``torch.no_grad()``: the graph for double backpropagation is built only when grad mode
        is on (training); in evaluation the result is detached. ``t`` is unused (autonomous
        systems).
        """
        if not torch.is_grad_enabled():
            kernel = self._evaluation_kernel()
            if kernel is not None:
                dxdt = kernel.evaluate(x)
                if dxdt is not None:
                    return dxdt
        self._check_input(x)
        if self.baseline:
            return self.differentiable_model(x)
        create_graph = torch.is_grad_enabled()
        net = self.differentiable_model
        conservative = solenoidal = None
        if self.field_type != "solenoidal":
            conservative = input_gradient(net, x, 0, create_graph)
        if self.field_type != "conservative":
            dF2 = input_gradient(net, x, 1, create_graph)
            n = self.input_dim // 2
            solenoidal = torch.cat([dF2[:, n:], -dF2[:, :n]], dim=1)
        if conservative is None:
            return solenoidal
        return conservative if solenoidal is None else conservative + solenoidal


    def numpy_time_derivative(self):
        """``dx/dt`` of numpy states by the evaluation kernel (``EnergyField.numpy``), where ``time_derivative``
        would take it: grad mode off, inside a rollout's frozen weights, the paper's tanh MLP; else None."""
        def call(y: np.ndarray) -> np.ndarray | None:
            if torch.is_grad_enabled():
                return None
            kernel = self._evaluation_kernel()
            return None if kernel is None else kernel.serve(y)
        return call

    def _evaluation_kernel(self):
        """The field as one ``hnn.models.tanh_mlp.EvaluationKernel`` (the evaluation path for a few states), or
        None when the network is not the paper's tanh MLP."""
        net = self._modules["differentiable_model"]
        if not isinstance(net, MLP):
            return None
        if self.baseline:
            return tanh_mlp.cached_kernel(self, "field", net, None)
        rows = FIELD_ROWS[self.field_type]
        return tanh_mlp.cached_kernel(self, "field", net, rows, lambda: self._fold(rows))

    def _fold(self, rows: tuple[int, ...]) -> torch.Tensor:
        """How d(F_k)/dx enters dx/dt for each k of ``rows``: F1's gradient as it is, F2's through M^T."""
        eye, hamilton = torch.eye(self.input_dim, device="cpu"), self.M.detach().cpu().T
        return torch.stack([{0: eye, 1: hamilton}[k] for k in rows])


class Baseline(HNN):
    """The paper's baseline: an MLP ``(batch, input_dim) -> dx/dt``, no H, any state it is given."""
    conservative = False
    takes = ANY_STATE

    def __init__(self, input_dim: int, differentiable_model: nn.Module, field_type: str = RunSettings.field_type):
        super().__init__(input_dim, differentiable_model, field_type, baseline=True)


def build_model(input_dim: int, hidden_dim: int = RunSettings.hidden_dim,
                nonlinearity: str = RunSettings.nonlinearity, baseline: bool = False,
                field_type: str = RunSettings.field_type) -> HNN:
    """The paper's model for one task: ``HNN(input_dim, MLP(input_dim, hidden_dim, out))``, or ``Baseline``.

    ``out`` is 2 (F1, F2) for the HNN and ``input_dim`` (dx/dt directly) for the baseline.
    """
    if baseline:
        return Baseline(input_dim, MLP(input_dim, hidden_dim, input_dim, nonlinearity), field_type)
    return HNN(input_dim, MLP(input_dim, hidden_dim, 2, nonlinearity), field_type=field_type)
