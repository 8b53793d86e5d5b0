"""A chain of N point masses on massless rods hanging from a fixed pivot, in a plane.

The system of the chain task (not one of the paper's six: its ``task.py`` keeps it out of
``analysis/reproduce.py``; ``analysis/peers.py`` trains it on the peers' protocols).

Generalized coordinates: q_k is the angle of rod k from the downward vertical (absolute, not
relative to rod k-1), k = 0 the rod at the pivot; bob k hangs at the end of rod k. With
mu_ij = sum_{k >= max(i, j)} m_k (the mass below both rods),

    M_ij(q) = mu_ij l_i l_j cos(q_i - q_j),      V(q) = -g sum_j mu_jj l_j cos q_j,
    H(q, p) = 1/2 p^T M(q)^-1 p + V(q),           p = M(q) qdot.

States are ``x = [q, p]`` of shape ``(batch, 2N)`` (canonical, for H and derivative training)
or ``z = [q, qdot]`` (what one observes, and what the CHNN protocol trains and rolls out on);
angles in radians, lengths in metres, masses in kg, time in seconds.

Two parameter sets, as the peers' code builds them (docs/peers.md):

- ``chnn_chain(N)``: CHNN's ``ChainPendulum(N)``, g = 9.81, masses and lengths 0.6 + 0.8 U(0, 1)
  drawn by ``numpy.random`` under seed 0 (N masses, then N lengths), assigned from the pivot
  outwards in *reverse* draw order (their constructor pops from the ends of the lists);
  ``unit=True`` for m = l = 1.
- ``lnn_double_pendulum()``: the LNN double pendulum, N = 2, m = l = 1, g = 9.8.

Start states as CHNN samples them (``sample_chnn_starts``): angles and angular velocities
N(0, 1); the bobs' Cartesian positions get N(0, 0.2^2) noise and their velocities become
3 (0.5 v + N(0, 0.4^2)); the result is projected back onto the rod constraints (Gauss-Newton
with the least-norm step, as theirs) and read off as angles.
"""
from __future__ import annotations

from dataclasses import dataclass

from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.cache import get_cached_dataset

HERE = Path(__file__).resolve().parent

NAME = "chain"
CHNN_G = 9.81
LNN_G = 9.8


@dataclass(frozen=True)
class Chain:
    """An N-bob chain: ``masses`` and ``lengths`` (from the pivot outwards, each ``(N,)``), gravity ``g``."""
    masses: tuple[float, ...]
    lengths: tuple[float, ...]
    g: float = CHNN_G

    def __post_init__(self):
        if len(self.masses) < 1 or len(self.masses) != len(self.lengths):
            raise ValueError(f"a chain needs N >= 1 bobs with one length each, got {len(self.masses)} masses "
                             f"and {len(self.lengths)} lengths")
        if min(self.masses) <= 0 or min(self.lengths) <= 0:
            raise ValueError(f"masses and lengths must be positive, got {self.masses} and {self.lengths}")

    @property
    def n(self) -> int:
        """The number of bobs (degrees of freedom)."""
        return len(self.masses)

    def _params(self, like: torch.Tensor):
        m = torch.tensor(self.masses, dtype=like.dtype, device=like.device)
        lengths = torch.tensor(self.lengths, dtype=like.dtype, device=like.device)
        below = m.flip(0).cumsum(0).flip(0)                  # mass at or below bob k, (N,)
        idx = torch.arange(self.n, device=like.device)
        mu = below[torch.maximum(idx[:, None], idx[None, :])]   # mu_ij, (N, N)
        return lengths, below, mu

    def _check(self, x: torch.Tensor, what: str = "x") -> torch.Tensor:
        x = torch.as_tensor(x)
        if x.dim() != 2 or x.shape[1] != 2 * self.n:
            raise ValueError(f"{what} must have shape (batch, {2 * self.n}) for a {self.n}-bob chain, "
                             f"got {tuple(x.shape)}")
        return x

    def mass_matrix(self, q: torch.Tensor) -> torch.Tensor:
        """M(q), ``(batch, N)`` -> ``(batch, N, N)``, symmetric positive definite."""
        lengths, _, mu = self._params(q)
        return mu * lengths[:, None] * lengths[None, :] * torch.cos(q[:, :, None] - q[:, None, :])

    def potential(self, q: torch.Tensor) -> torch.Tensor:
        """V(q) = -g sum_j mu_jj l_j cos q_j, ``(batch,)`` (zero with every rod horizontal)."""
        lengths, below, _ = self._params(q)
        return -self.g * (below * lengths * torch.cos(q)).sum(1)

    def max_potential(self) -> float:
        """max |V| = g sum_j mu_jj l_j, the chain hanging straight down (29.4 for the LNN pendulum)."""
        below = np.cumsum(self.masses[::-1])[::-1]
        return float(self.g * (below * np.asarray(self.lengths)).sum())

    def velocities(self, x: torch.Tensor) -> torch.Tensor:
        """``z = [q, qdot]`` of canonical states ``x = [q, p]``, both ``(batch, 2N)``."""
        x = self._check(x)
        q, p = x[:, :self.n], x[:, self.n:]
        return torch.cat([q, torch.linalg.solve(self.mass_matrix(q), p[..., None])[..., 0]], dim=1)

    def momenta(self, z: torch.Tensor) -> torch.Tensor:
        """``x = [q, p]`` of observed states ``z = [q, qdot]``, both ``(batch, 2N)``."""
        z = self._check(z, "z")
        q, v = z[:, :self.n], z[:, self.n:]
        return torch.cat([q, (self.mass_matrix(q) @ v[..., None])[..., 0]], dim=1)

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H(q, p), ``(batch, 2N)`` -> ``(batch,)``, in joules."""
        x = self._check(x)
        v = self.velocities(x)[:, self.n:]
        return 0.5 * (x[:, self.n:] * v).sum(1) + self.potential(x[:, :self.n])

    def energy(self, z: torch.Tensor) -> torch.Tensor:
        """The energy of observed states ``z = [q, qdot]``, ``(batch,)``: 1/2 qdot^T M qdot + V."""
        z = self._check(z, "z")
        q, v = z[:, :self.n], z[:, self.n:]
        kinetic = 0.5 * (v[:, None, :] @ self.mass_matrix(q) @ v[:, :, None])[:, 0, 0]
        return kinetic + self.potential(q)

    def dynamics(self, x: torch.Tensor) -> torch.Tensor:
        """Hamilton's equations in closed form, ``(batch, 2N) -> (batch, 2N)``.

        dq/dt = M^-1 p = v; dp_k/dt = -dH/dq_k = 1/2 v^T (dM/dq_k) v - dV/dq_k
        = -l_k v_k sum_j mu_kj l_j sin(q_k - q_j) v_j - g mu_kk l_k sin q_k.
        """
        x = self._check(x)
        q = x[:, :self.n]
        v = self.velocities(x)[:, self.n:]
        lengths, below, mu = self._params(x)
        coupling = mu * lengths[None, :] * torch.sin(q[:, :, None] - q[:, None, :])     # (batch, N, N)
        dp = -lengths * v * (coupling @ v[..., None])[..., 0] - self.g * below * lengths * torch.sin(q)
        return torch.cat([v, dp], dim=1)

    def observed_dynamics(self, z: torch.Tensor) -> torch.Tensor:
        """d/dt of observed states ``z = [q, qdot]``, ``(batch, 2N) -> (batch, 2N)``: (qdot, qddot),
        the derivative of qdot = M^-1 p along Hamilton's equations (what the LNN trains on)."""
        x = self.momenta(z)
        return torch.func.jvp(self.velocities, (x,), (self.dynamics(x),))[1]

    def cartesian(self, z: torch.Tensor) -> torch.Tensor:
        """Positions and velocities of every bob of observed states ``z = [q, qdot]``.

        ``(batch, 2N)`` -> ``(batch, 2, N, 2)``: [position | velocity, bob, (x, y)], pivot at the
        origin, y up. Any leading shape works: ``(..., 2N)`` -> ``(..., 2, N, 2)``.
        """
        q, v = z[..., :self.n], z[..., self.n:]
        lengths = torch.tensor(self.lengths, dtype=z.dtype, device=z.device)
        rods = torch.stack([torch.sin(q), -torch.cos(q)], dim=-1) * lengths[:, None]
        rod_velocities = torch.stack([torch.cos(q), torch.sin(q)], dim=-1) * (lengths * v)[..., None]
        return torch.stack([rods.cumsum(-2), rod_velocities.cumsum(-2)], dim=-3)

    def from_cartesian(self, cart: torch.Tensor) -> torch.Tensor:
        """Observed states ``z = [q, qdot]`` ``(batch, 2N)`` of bobs on the constraints ``(batch, 2, N, 2)``;
        angles in (-pi, pi]."""
        pos, vel = cart[:, 0], cart[:, 1]
        rods = pos - torch.cat([torch.zeros_like(pos[:, :1]), pos[:, :-1]], dim=1)
        rod_vel = vel - torch.cat([torch.zeros_like(vel[:, :1]), vel[:, :-1]], dim=1)
        q = torch.atan2(rods[..., 0], -rods[..., 1])
        qdot = (rods[..., 0] * rod_vel[..., 1] - rods[..., 1] * rod_vel[..., 0]) / (rods ** 2).sum(-1)
        return torch.cat([q, qdot], dim=1)

    def constraint_graph(self) -> hnn.models.ConstraintGraph:
        """The rods as an ``hnn.models.ConstraintGraph`` (what the Cartesian kinds are given): bob 0 tethered
        to the pivot at the origin by rod 0, bob k linked to bob k-1 by rod k; 2 dimensions."""
        return hnn.models.ConstraintGraph(self.n, 2, tethers=((0, (0.0, 0.0), self.lengths[0]),),
                                   links=tuple((k - 1, k, self.lengths[k]) for k in range(1, self.n)))

    def to_cartesian(self, z: torch.Tensor) -> torch.Tensor:
        """Flat Cartesian states [x, xdot] ``(..., 4N)`` (bob after bob, (x, y) each, then their
        velocities) of observed states ``z = [q, qdot]`` ``(..., 2N)``."""
        return self.cartesian(torch.as_tensor(z)).flatten(-3)

    def from_flat_cartesian(self, states: torch.Tensor) -> torch.Tensor:
        """Observed states ``z = [q, qdot]`` ``(batch, 2N)`` of flat Cartesian states ``(batch, 4N)`` on the rods."""
        states = torch.as_tensor(states)
        if states.dim() != 2 or states.shape[1] != 4 * self.n:
            raise ValueError(f"Cartesian states of a {self.n}-bob chain have shape (batch, {4 * self.n}), "
                             f"got {tuple(states.shape)}")
        return self.from_cartesian(states.reshape(len(states), 2, self.n, 2))

    def constraints(self, cart: torch.Tensor) -> torch.Tensor:
        """Rod constraints of Cartesian states ``(batch, 2, N, 2)`` -> ``(batch, 2N)``: |r_k|^2 - l_k^2
        and d/dt of it, 2 r_k . w_k (r_k, w_k: rod k's vector and its velocity)."""
        pos, vel = cart[:, 0], cart[:, 1]
        rods = pos - torch.cat([torch.zeros_like(pos[:, :1]), pos[:, :-1]], dim=1)
        rod_vel = vel - torch.cat([torch.zeros_like(vel[:, :1]), vel[:, :-1]], dim=1)
        lengths = torch.tensor(self.lengths, dtype=cart.dtype, device=cart.device)
        return torch.cat([(rods ** 2).sum(-1) - lengths ** 2, 2 * (rods * rod_vel).sum(-1)], dim=1)

    def project(self, cart: torch.Tensor, tol: float = 1e-12, max_iter: int = 500) -> torch.Tensor:
        """The Cartesian states ``(batch, 2, N, 2)`` moved onto the constraints by Gauss-Newton steps
        of least norm, -J^T (J J^T)^-1 Phi, each component clamped to half the states' RMS (as CHNN's
        projection), until the RMS violation is below ``tol``."""
        z = cart.detach().clone()
        flat = z.reshape(len(z), -1)

        def phi(row):
            return self.constraints(row.reshape(1, *z.shape[1:]))[0]
        jacobian = torch.func.vmap(torch.func.jacrev(phi))
        for _ in range(max_iter):
            violation = self.constraints(flat.reshape(z.shape))
            if violation.pow(2).mean().sqrt() < tol:
                return flat.reshape(z.shape)
            J = jacobian(flat)                                                 # (batch, 2N, 4N)
            step = -(J.transpose(1, 2) @ torch.linalg.solve(J @ J.transpose(1, 2), violation[..., None]))[..., 0]
            scale = flat.pow(2).mean().sqrt()
            flat = flat + step.clamp(-scale / 2, scale / 2)
        raise RuntimeError(f"the constraint projection did not reach tol={tol} in {max_iter} iterations")


def structure_holds(kind: str) -> bool:
    """Whether the chain has the structure a kind declares: the chain loses no energy (a
    ``dissipative`` kind models friction it does not have) and its kinetic energy depends on the
    angles, so H is not T(p) + V(q) in the coordinates a ``separable`` kind reads."""
    row = hnn.kinds.get_kind(kind)
    return not (row.dissipative or row.separable)


def observed_coordinates(kind: str) -> str:
    """The coordinates a model of ``kind`` sees the chain in: ``'velocity'`` [q, qdot] where it reads
    them (as they are, or mapped), else ``'cartesian'`` [x, xdot] of the bobs where it reads those
    (the constrained kinds), else a ValueError naming the fix."""
    row = hnn.kinds.get_kind(kind)
    for observed in ("velocity", "cartesian"):
        if row.reads(observed):
            return observed
    raise ValueError(f"the {kind} kind reads neither the chain's angles [q, qdot] nor its Cartesian [x, xdot]; "
                     "choose a kind that does (hnn.MODEL_KINDS declares what each reads)")


def cartesian_dataset(chain: Chain, data: dict) -> dict:
    """``data`` (observed [q, qdot] rows and their d/dt) in flat Cartesian coordinates [x, xdot]
    ``(rows, 4N)``: positions by ``to_cartesian``, their d/dt along the same path by its Jacobian."""
    out = dict(data)
    for split in ("", "test_"):
        z = torch.as_tensor(data[split + "x"], dtype=torch.float64)
        dz = torch.as_tensor(data[split + "dxdt"], dtype=torch.float64)
        states, rates = torch.func.jvp(chain.to_cartesian, (z,), (dz,))
        out[split + "x"], out[split + "dxdt"] = states.numpy(), rates.numpy()
    return {**out, "state": "cartesian"}


def chain_for(bobs: int, unit: bool = False, protocol: str = "chnn") -> Chain:
    """The chain of a protocol: ``chnn_chain(bobs, unit)``, or the LNN double pendulum."""
    return lnn_double_pendulum() if protocol == "lnn" else chnn_chain(bobs, unit)


def _chnn_draws(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.RandomState(seed)
    return np.array([0.6 + 0.8 * rng.rand() for _ in range(2 * n)])


def chnn_chain(n: int, unit: bool = False) -> Chain:
    """CHNN's ``ChainPendulum(n)``: random masses and lengths (see the module docstring), or m = l = 1."""
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"a chain needs N >= 1 bobs, got {n!r}; e.g. --bobs 2 for the double pendulum")
    if unit:
        return Chain((1.0,) * n, (1.0,) * n, CHNN_G)
    draws = _chnn_draws(int(n))
    return Chain(tuple(draws[:n][::-1].tolist()), tuple(draws[n:][::-1].tolist()), CHNN_G)


def lnn_double_pendulum() -> Chain:
    """The LNN paper's double pendulum: m = l = 1, g = 9.8."""
    return Chain((1.0, 1.0), (1.0, 1.0), LNN_G)


def sample_chnn_starts(chain: Chain, count: int, generator: torch.Generator) -> torch.Tensor:
    """``count`` observed start states ``z = [q, qdot]`` ``(count, 2N)``, float64, drawn as CHNN
    draws them (module docstring), in their order: angles and rates ``(count, 2, N)``, then the
    position noise, then the velocity noise ``(count, N, 2)`` each."""
    n = chain.n
    angles = torch.randn(count, 2, n, generator=generator).to(torch.float64)
    cart = chain.cartesian(angles.reshape(count, 2 * n))
    pos_noise = torch.randn(count, n, 2, generator=generator).to(torch.float64)
    vel_noise = torch.randn(count, n, 2, generator=generator).to(torch.float64)
    cart = torch.stack([cart[:, 0] + 0.2 * pos_noise, 3 * (0.5 * cart[:, 1] + 0.4 * vel_noise)], dim=1)
    return chain.from_cartesian(chain.project(cart))


def sample_lnn_starts(count: int, generator: torch.Generator, train: bool = True) -> torch.Tensor:
    """LNN double-pendulum starts ``z = [q, qdot]`` ``(count, 4)``, float64: angles U[0, 2 pi];
    rates U[-10, 10] for training, U[0, 0.1] for the test rollouts."""
    q = 2 * np.pi * torch.rand(count, 2, generator=generator, dtype=torch.float64)
    u = torch.rand(count, 2, generator=generator, dtype=torch.float64)
    return torch.cat([q, 20 * u - 10 if train else 0.1 * u], dim=1)


def trajectories(chain: Chain, z0: torch.Tensor, t_eval, rtol: float = 1e-10, atol: float = 1e-10) -> torch.Tensor:
    """The true paths ``z = [q, qdot]`` ``(batch, len(t_eval), 2N)`` from observed starts ``z0``
    ``(batch, 2N)``: dopri5 on H in float64 (one step size per trajectory)."""
    x0 = chain.momenta(torch.as_tensor(z0, dtype=torch.float64))
    with torch.no_grad():
        xs = hnn.rollout(chain.dynamics, x0, t_eval, method="dopri5", rtol=rtol, atol=atol)
    return chain.velocities(xs.reshape(-1, 2 * chain.n)).reshape(xs.shape)



def _paths_dataset(chain: Chain, seed: int, n_train: int, n_test: int, points: int, dt: float) -> dict:
    t_eval = dt * np.arange(points)
    arrays = {}
    for split, count, offset in (("", n_train, 0), ("test_", n_test, 2)):
        # CHNN's seeds: training trajectories under seed 0, test under seed 2 (validation 1)
        z0 = sample_chnn_starts(chain, count, torch.Generator().manual_seed(seed + offset))
        z = trajectories(chain, z0, t_eval).reshape(-1, 2 * chain.n)
        arrays[split + "x"] = z.numpy()
        arrays[split + "dxdt"] = chain.observed_dynamics(z).numpy()
    return {**arrays, "dt": float(dt), "t_eval": t_eval}


def _states_dataset(chain: Chain, seed: int, n_train: int, n_test: int) -> dict:
    arrays = {}
    for split, count, offset in (("", n_train, 0), ("test_", n_test, 1)):
        z = sample_lnn_starts(count, torch.Generator().manual_seed(seed + offset), train=True)
        arrays[split + "x"] = z.numpy()
        arrays[split + "dxdt"] = chain.observed_dynamics(z).numpy()
    return arrays


def get_dataset(bobs: int = 2, unit: bool = False, protocol: str = "chnn", seed: int = 0, n_train: int = 800,
                n_test: int = 100, points: int = 100, dt: float = 0.03, save_dir=HERE) -> dict:
    """The observed states ``z = [q, qdot]`` (float64, ``(rows, 2 * bobs)``) and their ``d/dt``.

    ``protocol='chnn'``: ``n_train`` and ``n_test`` true paths of ``points`` states ``dt`` apart
    from CHNN's start law (rows path after path; ``t_eval`` and ``dt`` let ``--objective
    trajectory`` cut them into snippets), on ``chnn_chain(bobs, unit)``. ``protocol='lnn'``:
    the LNN double pendulum's derivative data, states q ~ U[0, 2 pi], qdot ~ U[-10, 10] (no
    paths; ``bobs`` must be 2). ``"state": "velocity"`` tells the objectives the second half of
    a state is qdot, not p. Cached as an .npz in ``save_dir``.
    """
    if protocol not in ("chnn", "lnn"):
        raise ValueError(f"unknown protocol {protocol!r}; choose 'chnn' (Finzi et al. 2020) or 'lnn' (Cranmer et al. 2020)")
    if protocol == "lnn" and (bobs != 2 or unit):
        raise ValueError(f"the LNN protocol is the double pendulum with m = l = 1: pass --bobs 2 without --unit, "
                         f"got bobs={bobs}, unit={unit}")
    chain = chain_for(bobs, unit, protocol)
    params = {"bobs": bobs, "unit": unit, "protocol": protocol, "seed": seed, "n_train": n_train, "n_test": n_test,
              "points": points, "dt": dt, "version": 1}

    def build():
        if protocol == "lnn":
            return _states_dataset(chain, seed, n_train, n_test)
        return _paths_dataset(chain, seed, n_train, n_test, points, dt)
    data = get_cached_dataset(save_dir, f"{NAME}{bobs}-{protocol}", params, build,
                                        describe=lambda d: f"{len(d['x'])} training states of a {bobs}-bob chain")
    return {**data, "state": "velocity"}
