"""Two model kinds for mechanical systems, whose kinetic energy is quadratic in the velocities.

- ``MechanicalHNN``: H(q, p) = 1/2 p^T M^-1(q) p + V(q), with M^-1(q) = L(q) L(q)^T + eps I
  from a learned lower-triangular L(q) (softplus diagonal): positive definite by construction
  for every q and every weight. The form of Lagrangian mechanics in generalized coordinates,
  and of the "HNN" of Finzi, Wang & Wilson (2020) on pendulum chains.
- ``SecondOrderNODE``: dq/dt = v, dv/dt = f(q, v), an MLP f: the baseline with second-order
  structure and no energy (Gruver et al. 2022).

Both take ``periodic=True`` when q are angles: the networks then see (cos q, sin q), so every
learned function is 2 pi-periodic in q.

Neither field is separable, so neither may be rolled out with ``leapfrog`` or ``yoshida4``'s
default base (``hnn.rollout`` would silently be wrong, ``hnn.objectives.trajectory`` refuses): use
``'midpoint'`` (symplectic for any H, so for the MechanicalHNN), ``'dopri5'`` or ``'rk4'``.

    model = hnn.MechanicalHNN(4, hidden_dim=200, periodic=True)
    x = model.state_from_observed(z)          # z = [q, qdot] -> x = [q, p], p = M(q) qdot
    traj = hnn.rollout(model.time_derivative, x, t_eval, method="dopri5", rtol=1e-7)
    z_t = model.observed_from_state(traj.reshape(-1, 4))

The model kinds ``'mechanical'`` and ``'second_order'`` (rows of ``hnn.MODEL_KINDS``).
"""
from __future__ import annotations

import warnings

import torch
from torch import nn

from ..interface import Model, gradient_of
from ..modes import in_model_axis
from ..settings import RunSettings
from .mlp import MLP


def check_width(input_dim, kind: str) -> int:
    """n, the degrees of freedom of a state of width ``input_dim`` = 2n; a clear error otherwise."""
    if not isinstance(input_dim, int) or isinstance(input_dim, bool) or input_dim < 2 or input_dim % 2:
        raise ValueError(f"{kind} needs a state [q, p] or [q, qdot] of even width input_dim >= 2, "
                         f"got {input_dim!r}; pass 2 * (degrees of freedom)")
    return input_dim // 2


def embed_angles(q: torch.Tensor, periodic: bool) -> torch.Tensor:
    """What a network reads of positions ``(batch, n)``: ``[cos q, sin q]`` ``(batch, 2n)`` for angles, else q."""
    return torch.cat([torch.cos(q), torch.sin(q)], dim=1) if periodic else q


class StateCheckedModel(Model):
    """A ``Model`` whose ``_check_input`` names the expected ``(batch, input_dim)`` on a wrong shape."""
    input_dim: int

    def _check_input(self, x: torch.Tensor) -> None:
        if x.dim() != 2 or x.shape[1] != self.input_dim:
            raise ValueError(f"expected a state of shape (batch, {self.input_dim}), got {tuple(x.shape)}")


class MechanicalHNN(StateCheckedModel):
    """H(q, p) = 1/2 p^T M^-1(q) p + V(q) on ``x = [q, p]`` of shape ``(batch, 2n)``.

    Args:
        input_dim: 2n, the width of x.
        hidden_dim: units per hidden layer of the MLP of q (``hnn.MLP``) whose outputs are V(q)
            and the n(n+1)/2 entries of L(q).
        nonlinearity: their activation (smooth ones only: the field differentiates them).
        periodic: q are angles (the networks see cos q, sin q).
        eps: the floor of M^-1's eigenvalues (units of M^-1, e.g. 1 / (kg m^2) for angles).

    Valid where T is quadratic in p with a configuration-dependent mass (any holonomic
    mechanical system in generalized coordinates). Fit on dx/dt by the L2 loss it learns M^-1
    only as well as that loss weighs dq/dt = M^-1 p: where dp/dt is far larger (heavy bodies,
    strong gravity) M^-1 can come out wrong in one direction while the loss is low (docs/arm.md:
    the two-link arm, 3% M^-1 error at 1 kg links, 31% at 10 kg); ``--balance`` (on by default where the
    components' sizes differ over 10x: ``hnn.balance``) weighs each by its own size (docs/stress.md,
    "Balanced loss"). Not separable: roll out with ``midpoint``
    (symplectic for any H) or ``dopri5``; ``hnn.objectives.trajectory`` refuses ``leapfrog`` for it.
    Declares ``maps = ('velocity',)``: observed [q, qdot] map to [q, p] through its mass matrix.
    """
    conservative = True
    maps = ("velocity",)

    def __init__(self, input_dim: int, hidden_dim: int = RunSettings.hidden_dim,
                 nonlinearity: str = RunSettings.nonlinearity, periodic: bool = False,
                 eps: float = 1e-4):
        super().__init__()
        self.n = check_width(input_dim, "MechanicalHNN")
        if not eps >= 0:
            raise ValueError(f"eps must be >= 0 (M^-1's eigenvalue floor), got {eps!r}")
        self.input_dim, self.periodic, self.eps = input_dim, bool(periodic), float(eps)
        # one MLP of q for V and the n(n+1)/2 entries of L: half the matrix products of two nets
        self.net = MLP(2 * self.n if periodic else self.n, hidden_dim, 1 + self.n * (self.n + 1) // 2, nonlinearity)
        rows, cols = torch.tril_indices(self.n, self.n)
        self.register_buffer("_rows", rows, persistent=False)
        self.register_buffer("_cols", cols, persistent=False)
        # the same placement as a 0/1 matrix (entries @ place), for vmap over models (hnn.modes.model_axis),
        # which has no fast rule for the index_put below
        place = torch.zeros(len(rows), self.n * self.n)
        place[torch.arange(len(rows)), rows * self.n + cols] = 1
        self.register_buffer("_place", place, persistent=False)

    def check_data_scale(self, x, dxdt) -> None:
        """Warn where canonical data ``x``, ``dxdt`` ``(rows, 2n)`` need an M^-1 near or below ``eps``, the
        floor of its eigenvalues: their size, rms(dq/dt) / rms(p), is what M^-1 must reach, and below
        10 eps the model cannot (docs/stress.md: q in 10^-3 units left the spring's error at 300)."""
        x, dxdt = torch.as_tensor(x, device="cpu"), torch.as_tensor(dxdt, device="cpu")     # a check on the data
        p_rms = x[:, self.n:].double().pow(2).mean().sqrt()
        size = float(dxdt[:, :self.n].double().pow(2).mean().sqrt() / p_rms) if p_rms > 0 else float("inf")
        if size < 10 * self.eps:
            warnings.warn(f"the data's M^-1 is about {size:.3g} (rms dq/dt / rms p), within 10x of MechanicalHNN's "
                          f"eigenvalue floor eps={self.eps:g}: it cannot be learned there. Rescale q and p so "
                          "that Hamilton's equations still hold (docs/python.md, 'Scale your states')", stacklevel=3)

    def potential_and_factor(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(V(q), L(q))`` from one pass of the MLP, ``(batch, n)`` -> ``(batch,)`` and ``(batch, n, n)``,
        L lower triangular with a positive diagonal. Override it to plug in a known V and L."""
        out = self.net(embed_angles(q, self.periodic))
        entries = out[:, 1:]
        entries = torch.where(self._rows == self._cols, nn.functional.softplus(entries), entries)
        if in_model_axis():
            return out[:, 0], (entries @ self._place).reshape(len(q), self.n, self.n)
        L = entries.new_zeros(len(q), self.n, self.n)
        L[:, self._rows, self._cols] = entries
        return out[:, 0], L

    def potential(self, q: torch.Tensor) -> torch.Tensor:
        """V(q), ``(batch, n)`` -> ``(batch,)``."""
        return self.potential_and_factor(q)[0]

    def inverse_mass(self, q: torch.Tensor) -> torch.Tensor:
        """M^-1(q) = L L^T + eps I, ``(batch, n, n)``: symmetric positive definite."""
        L = self.potential_and_factor(q)[1]
        return L @ L.transpose(1, 2) + self.eps * torch.eye(self.n, dtype=q.dtype, device=q.device)

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H = 1/2 |L(q)^T p|^2 + eps/2 |p|^2 + V(q) = 1/2 p^T M^-1(q) p + V(q), ``(batch,)``."""
        self._check_input(x)
        q, p = x[:, :self.n], x[:, self.n:]
        V, L = self.potential_and_factor(q)
        u = (L.transpose(1, 2) @ p[:, :, None])[..., 0]
        return 0.5 * (u.pow(2).sum(1) + self.eps * p.pow(2).sum(1)) + V

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        """``dx/dt = (dH/dp, -dH/dq)`` by autograd, ``(batch, 2n)``; a graph for training only in grad mode."""
        self._check_input(x)
        dH = gradient_of(self.hamiltonian, x)
        return torch.cat([dH[:, self.n:], -dH[:, :self.n]], dim=1)

    def state_from_observed(self, z: torch.Tensor) -> torch.Tensor:
        """``x = [q, p]`` with p = M(q) qdot, from observed ``z = [q, qdot]``, both ``(batch, 2n)``."""
        self._check_input(z)
        q, v = z[:, :self.n], z[:, self.n:]
        p = torch.linalg.solve(self.inverse_mass(q), v[..., None])[..., 0]
        return torch.cat([q, p], dim=1)

    def observed_time_derivative(self, z: torch.Tensor) -> torch.Tensor:
        """d/dt of observed ``z = [q, qdot]`` along the model's flow, ``(batch, 2n)``: (qdot, qddot),
        qddot = d/dt [M^-1(q) p] = (D_q M^-1 . qdot) p + M^-1 dp/dt (the derivative objective's
        prediction where a task observes velocities); a graph for training only in grad mode."""
        self._check_input(z)
        x = self.state_from_observed(z)
        dx = self.time_derivative(x)
        q, p, qdot = x[:, :self.n], x[:, self.n:], dx[:, :self.n]
        with torch.enable_grad() if torch.is_grad_enabled() else torch.no_grad():
            mobility, along = torch.func.jvp(lambda q: self.inverse_mass(q), (q,), (qdot,))
        qddot = (along @ p[..., None] + mobility @ dx[:, self.n:, None])[..., 0]
        return torch.cat([qdot, qddot], dim=1)

    def observed_from_state(self, x: torch.Tensor) -> torch.Tensor:
        """``z = [q, qdot]`` with qdot = M^-1(q) p = dH/dp, from ``x = [q, p]``, both ``(batch, 2n)``."""
        self._check_input(x)
        q, p = x[:, :self.n], x[:, self.n:]
        return torch.cat([q, (self.inverse_mass(q) @ p[..., None])[..., 0]], dim=1)


class SecondOrderNODE(StateCheckedModel):
    """dq/dt = v, dv/dt = f(q, v) on ``z = [q, v]`` of shape ``(batch, 2n)``, f an ``hnn.MLP``.

    Valid on states of positions and *velocities* (v = dq/dt), e.g. trajectories observed as
    [q, qdot]; on canonical [q, p] it is wrong unless p = qdot (unit mass). No energy, not
    symplectic, not separable: roll out with ``rk4`` or ``dopri5``. Declares ``coordinates =
    'velocity'`` and takes no other: the objectives refuse it on canonical states.
    """
    coordinates = "velocity"
    takes = {"cartesian": "positions and velocities of bodies: a second-order field of any state [q, qdot]"}

    def __init__(self, input_dim: int, hidden_dim: int = RunSettings.hidden_dim,
                 nonlinearity: str = RunSettings.nonlinearity, periodic: bool = False):
        super().__init__()
        self.n = check_width(input_dim, "SecondOrderNODE")
        self.input_dim, self.periodic = input_dim, bool(periodic)
        self.acceleration_net = MLP(3 * self.n if periodic else input_dim, hidden_dim, self.n, nonlinearity)

    def acceleration(self, z: torch.Tensor) -> torch.Tensor:
        """f(q, v), ``(batch, 2n)`` -> ``(batch, n)``."""
        q, v = z[:, :self.n], z[:, self.n:]
        return self.acceleration_net(torch.cat([embed_angles(q, self.periodic), v], dim=1))

    def time_derivative(self, z: torch.Tensor, t=None) -> torch.Tensor:
        """``dz/dt = (v, f(q, v))``, ``(batch, 2n)``."""
        self._check_input(z)
        return torch.cat([z[:, self.n:], self.acceleration(z)], dim=1)

