"""Model kinds with more structure than the paper's HNN: a separable H, and H plus dissipation.

- ``SeparableHNN``: H(q, p) = T(p) + V(q), one MLP sees only p and one only q. Its field
  ``(dT/dp, -dV/dq)`` reads p alone in dq/dt and q alone in dp/dt, so explicit ``leapfrog`` and
  ``yoshida4`` are exactly symplectic for the *learned* model, at one field call per stage.
- ``DissipativeHNN``: the Helmholtz split of Sosanya & Greydanus, "Dissipative Hamiltonian Neural
  Networks" (2022): dx/dt = J grad H + grad D, a conservative H and a dissipative potential D
  learned together from dx/dt. The split is unique only up to a harmonic pair (J grad phi =
  grad psi), but the Laplacians are fixed by the field: lap H = -rot f and lap D = div f.

State ``x = [q, p]`` of shape ``(batch, 2n)``; every scalar (H, T, V, D) has shape ``(batch,)``.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from . import tanh_mlp
from ..interface import UNIT_MASS, Model, gradient_of
from ..settings import RunSettings
from .hamiltonian import HNN, permutation_tensor
from .mlp import MLP

_BLOCK_MAX_WIDTH = 128     # SeparableHNN: both networks as one block network up to this many units together


def _check_even(input_dim: int, kind: str) -> int:
    if not isinstance(input_dim, int) or input_dim < 2 or input_dim % 2:
        raise ValueError(f"{kind} needs x = [q, p] of even width input_dim >= 2, got {input_dim!r}")
    return input_dim // 2


def scalar_gradient(net: nn.Module, x: torch.Tensor, create_graph: bool) -> torch.Tensor:
    """d(net(x)[:, 0])/dx, ``(batch, width of x)``: the MLP's closed form where it applies, else autograd."""
    if isinstance(net, MLP) and net._closed_form_applies():
        return net.input_gradient(x, 0, create_graph)
    return gradient_of(lambda x_in: net(x_in)[:, 0], x, create_graph)


class SeparableHNN(Model):
    """H(q, p) = T(p) + V(q), each an MLP of ``hidden_dim`` units on its half of ``x = [q, p]``."""
    conservative = True
    separable = True
    takes = UNIT_MASS

    def __init__(self, input_dim: int, hidden_dim: int = RunSettings.hidden_dim,
                 nonlinearity: str = RunSettings.nonlinearity):
        super().__init__()
        self.n = _check_even(input_dim, "SeparableHNN")
        self.input_dim = input_dim
        self.kinetic_net = MLP(self.n, hidden_dim, 1, nonlinearity)
        self.potential_net = MLP(self.n, hidden_dim, 1, nonlinearity)

    def _check_input(self, x: torch.Tensor) -> None:
        if x.dim() != 2 or x.shape[1] != self.input_dim:
            raise ValueError(f"expected x of shape (batch, {self.input_dim}), got {tuple(x.shape)}")

    def kinetic(self, p: torch.Tensor) -> torch.Tensor:
        """T(p), ``(batch, n)`` -> ``(batch,)``."""
        return self.kinetic_net(p)[:, 0]

    def potential(self, q: torch.Tensor) -> torch.Tensor:
        """V(q), ``(batch, n)`` -> ``(batch,)``."""
        return self.potential_net(q)[:, 0]

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H = T(p) + V(q), ``(batch,)``."""
        self._check_input(x)
        return self.kinetic(x[:, self.n:]) + self.potential(x[:, :self.n])

    def _kernel(self, name: str, x: torch.Tensor):
        """The evaluation kernel of ``kinetic_net`` or ``potential_net`` if it serves ``x``, else None."""
        if torch.is_grad_enabled():
            return None
        net = getattr(self, name)
        kernel = tanh_mlp.cached_kernel(self, name, net, (0,), lambda: torch.eye(self.n, device="cpu")[None]) \
            if isinstance(net, MLP) else None
        return kernel if kernel is not None and kernel.serves(x) else None

    def _block_kernel(self, x: torch.Tensor):
        """Both networks as one of their summed width with block-diagonal weights, if it serves ``x``:
        its scalar is H = T(p) + V(q) and the field Hamilton's equations of it, in one kernel call.
        For narrow networks only (at most ``_BLOCK_MAX_WIDTH`` units together), where the call's
        overhead outweighs the products; wider ones run as two kernels (the block's products would
        cost twice the two networks' own)."""
        if torch.is_grad_enabled():
            return None
        kinetic, potential = self._modules["kinetic_net"], self._modules["potential_net"]
        if not (isinstance(kinetic, MLP) and isinstance(potential, MLP) and potential._closed_form_applies()
                and kinetic.linear2.out_features + potential.linear2.out_features <= _BLOCK_MAX_WIDTH):
            return None
        kernel = tanh_mlp.cached_kernel(self, "block", kinetic, (0,), lambda: permutation_tensor(self.input_dim, "cpu").T[None],
                                        self._block_weights)
        return kernel if kernel is not None and kernel.serves(x) else None

    def _block_weights(self) -> tuple:
        """``(W1, b1, W2, b2, W3)`` of the block network: hidden units of T read p, those of V read q."""
        (k1, kb1, k2, kb2, k3), (v1, vb1, v2, vb2, v3) = (tanh_mlp.mlp_weights(net) for net in
                                                          (self.kinetic_net, self.potential_net))
        W1 = torch.cat([torch.cat([torch.zeros_like(k1), k1], 1), torch.cat([v1, torch.zeros_like(v1)], 1)])
        return W1, torch.cat([kb1, vb1]), torch.block_diag(k2, v2), torch.cat([kb2, vb2]), torch.cat([k3, v3], 1)

    def kinetic_gradient(self, p: torch.Tensor) -> torch.Tensor:
        """dT/dp = dq/dt, ``(batch, n)`` -> ``(batch, n)``: the half of the field that reads p alone."""
        kernel = self._kernel("kinetic_net", p)
        return kernel(p) if kernel is not None else scalar_gradient(self.kinetic_net, p, torch.is_grad_enabled())

    def potential_gradient(self, q: torch.Tensor) -> torch.Tensor:
        """dV/dq = -dp/dt, ``(batch, n)`` -> ``(batch, n)``: the half of the field that reads q alone."""
        kernel = self._kernel("potential_net", q)
        return kernel(q) if kernel is not None else scalar_gradient(self.potential_net, q, torch.is_grad_enabled())

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        """``dx/dt = (dT/dp, -dV/dq)``, ``(batch, 2n)``; a graph for training only in grad mode."""
        self._check_input(x)
        block = self._block_kernel(x)
        if block is not None:
            return block(x)
        q, p = x[:, :self.n], x[:, self.n:]
        kinetic, potential = self._kernel("kinetic_net", p), self._kernel("potential_net", q)
        if kinetic is not None and potential is not None:
            dV = potential.numpy(q.detach().numpy())
            return torch.from_numpy(np.concatenate([kinetic.numpy(p.detach().numpy()), np.negative(dV, out=dV)], 1))
        return torch.cat([self.kinetic_gradient(p), -self.potential_gradient(q)], dim=1)


class DissipativeHNN(HNN):
    """dx/dt = J grad H + grad D: the paper's HNN with both fields of one MLP (F2 = H, F1 = D).
    It has an H (``hamiltonian``), but its flow loses it on purpose: not ``conservative``."""
    conservative = False
    dissipative = True

    def __init__(self, input_dim: int, hidden_dim: int = RunSettings.hidden_dim,
                 nonlinearity: str = RunSettings.nonlinearity):
        _check_even(input_dim, "DissipativeHNN")
        super().__init__(input_dim, MLP(input_dim, hidden_dim, 2, nonlinearity), field_type="both")

    def dissipation(self, x: torch.Tensor) -> torch.Tensor:
        """The dissipative potential D = F1 at ``x``, ``(batch,)``: its gradient is the non-conservative part."""
        return self.forward(x)[0].squeeze(1)
