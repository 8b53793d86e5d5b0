"""The adaptive solvers a user would otherwise call on a learned field: torchdiffeq's ``odeint``
(``dopri5``, ``dopri8``; the ``bench`` extra) and scipy's ``solve_ivp`` (``RK45``, ``DOP853``), each
called as its documentation shows, on the same field ``hnn.rollout`` steps.

    peer = PEERS["torchdiffeq dopri5"]
    if peer.available():
        traj = peer.run(field, x0, t, rtol=1e-8, atol=1e-8)     # (batch, len(t), dim), as hnn.rollout

Each runs as ``hnn.rollout`` runs its own methods, so that the integrators are compared and not the
field's set-up: without autograd, the weights frozen (the field runs as its kernel,
``hnn.modes.frozen_weights``) and, for at most ``SMALL_BATCH_ROWS`` states, on one torch thread.
torchdiffeq steps the batch as one tensor, scipy the flattened batch as one vector: one step size
for the whole batch, whose error norm is the RMS over every state (ours: one per trajectory).
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

import hnn
from hnn.integrators.integrate import SMALL_BATCH_ROWS
from hnn.threads import torch_threads


def _torchdiffeq(method: str):
    def run(field, x0: torch.Tensor, t: np.ndarray, rtol: float, atol: float) -> torch.Tensor:
        import torchdiffeq
        times = torch.as_tensor(t, dtype=x0.dtype)
        traj = torchdiffeq.odeint(lambda s, x: field(x), x0, times, method=method, rtol=rtol, atol=atol)
        return traj.transpose(0, 1)         # odeint gives (len(t), batch, dim)
    return run


def _scipy(method: str):
    def run(field, x0: torch.Tensor, t: np.ndarray, rtol: float, atol: float) -> torch.Tensor:
        from scipy.integrate import solve_ivp
        batch, dim = x0.shape

        def fun(s, y):
            return field(torch.from_numpy(y.reshape(batch, dim))).numpy().reshape(-1)
        sol = solve_ivp(fun, (t[0], t[-1]), x0.numpy().reshape(-1), method=method, t_eval=t, rtol=rtol, atol=atol)
        if not sol.success:
            raise hnn.DivergenceError(f"scipy {method} (rtol={rtol:g}) failed: {sol.message}")
        return torch.from_numpy(np.ascontiguousarray(sol.y.reshape(batch, dim, len(t)).transpose(0, 2, 1)))
    return run


@dataclass(frozen=True)
class Peer:
    """One peer's adaptive solver: ``name`` in reports, the ``package`` it comes from, its ``order``
    (of the solution it advances) and ``stepper(field, x0, t, rtol, atol)`` returning the path."""
    name: str
    package: str
    order: int
    stepper: Callable[..., torch.Tensor]

    def available(self) -> bool:
        """Whether its package imports here (torchdiffeq is an optional extra: ``pip install -e '.[bench]'``)."""
        try:
            importlib.import_module(self.package)
        except ImportError:
            return False
        return True

    def version(self) -> str | None:
        return importlib.import_module(self.package).__version__ if self.available() else None

    def run(self, field, x0: torch.Tensor, t, rtol: float, atol: float, stats: dict | None = None) -> torch.Tensor:
        """``(batch, len(t), dim)`` from ``x0`` ``(batch, dim)`` (CPU) at the times ``t`` (ascending), with
        ``field`` as ``hnn.rollout`` would step it (a model's declared ``field`` or a function); ``stats``,
        if given, gets ``nfev``: the batched calls of the field, as ``hnn.rollout``'s."""
        if isinstance(field, hnn.Model):
            field = field.field
        if isinstance(field, hnn.interface.EnergyField):
            field = field.whole
        t = np.asarray(t, dtype=np.float64)
        if stats is not None:
            plain, stats["nfev"] = field, 0

            def field(x):
                stats["nfev"] += 1
                return plain(x)
        with torch.no_grad(), hnn.modes.frozen_weights(), torch_threads(1 if len(x0) <= SMALL_BATCH_ROWS else None):
            return self.stepper(field, x0, t, rtol, atol)


PEERS: dict[str, Peer] = {peer.name: peer for peer in (
    Peer("torchdiffeq dopri5", "torchdiffeq", 5, _torchdiffeq("dopri5")),
    Peer("torchdiffeq dopri8", "torchdiffeq", 8, _torchdiffeq("dopri8")),
    Peer("scipy RK45", "scipy", 5, _scipy("RK45")),
    Peer("scipy DOP853", "scipy", 8, _scipy("DOP853")),
)}


def available(names=None) -> list[Peer]:
    """The peers (of ``names``, default all) whose package is installed."""
    return [PEERS[name] for name in (names or PEERS) if PEERS[name].available()]


def versions() -> dict[str, str | None]:
    """``{package: version}`` of every peer's package (None where it is not installed)."""
    return {peer.package: peer.version() for peer in PEERS.values()}
