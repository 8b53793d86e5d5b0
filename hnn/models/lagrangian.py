"""The Lagrangian neural network (LNN, Cranmer, Greydanus, Hoyer, Battaglia, Spergel & Ho 2020): a
black-box L(q, qdot), one MLP, whose accelerations come from the Euler-Lagrange equations:

    d/dt dL/dqdot = dL/dq   =>   qddot = (d2L/dqdot2)^-1 [dL/dq - (d2L/dqdot dq) qdot]

on observed ``z = [q, qdot]`` of shape ``(batch, 2n)`` (``coordinates = 'velocity'``): no canonical
momenta, no mass matrix, any L. The derivatives are batched autograd passes: dL/dz once, then one
pass per qdot_i for the row d(dL/dqdot_i)/dz (n + 1 backward passes over the whole batch, about half
the time of a per-state ``vmap(jacfwd(grad))``: docs/speed.md). Where d2L/dqdot2 is singular the
equations do not determine qddot: ``time_derivative`` raises ``SingularLagrangianError`` naming the
states (singular to working precision, ``singular_condition``, judged on the matrix scaled by its diagonal,
``equilibrated_condition``, so the same physics gets the same verdict in any units). ``solve='pinv'`` solves as LNN's own code does (MilesCranmer/lagrangian_nns, ``lnn.py``:
``jnp.linalg.pinv`` of d2L/dqdot2, whose default cutoff drops singular values below 10 n eps of the
largest): where every singular value lies above that cutoff the pseudo-inverse is the inverse, so there
the plain solve is used (the same qddot, bit for bit; ``tests/test_lagrangian.py``), and at the states
where one lies below it the pseudo-inverse's minimum-norm qddot, counted in ``pinv_states``. Measured on
the peers' chains (docs/stress.md, "The LNN solved as its authors solve it"): the runs the plain solve
stopped stop at the same step with it, their RK4 snippet diverging, so the error stays the default.

Its energy E(q, qdot) = qdot . dL/dqdot - L is conserved by its flow for any weights (the
Legendre transform of L, the Hamiltonian in velocity coordinates): the kind declares
``conservative`` with ``hamiltonian(z) = energy(z)``, what the energy metrics read. Its flow is
not S grad E in [q, qdot], so its ``field`` is the plain ``time_derivative``: a solver that reads
an H (``'discrete_gradient'``) refuses it; roll out with ``dopri5``, ``rk4`` or ``midpoint``.

    model = hnn.models.LagrangianNN(4, hidden_dim=128, nonlinearity="softplus")
    zdot = model.time_derivative(z)             # (batch, 4): [qdot, qddot]
    E = model.energy(z)                          # (batch,)

The model kind ``'lagrangian'`` (a row of ``hnn.MODEL_KINDS``).
"""
from __future__ import annotations

import torch
from torch.func import vmap

from ..errors import DivergenceError
from ..modes import in_model_axis
from .mechanical import check_width, embed_angles, StateCheckedModel
from ..names import LNN_SOLVES
from ..settings import RunSettings
from .mlp import MLP


def equilibrated_condition(hess: torch.Tensor) -> torch.Tensor:
    """The 2-norm condition number ``(batch,)`` of each d2L/dqdot2 ``(batch, n, n)`` scaled by its diagonal,
    D^-1/2 M D^-1/2 with D = |diag M| (a row whose diagonal is 0 scaled by its largest entry; inf where the
    matrix is singular or not finite).

    Why scaled: a change of the units of L, of time or of any one q_i is M -> c S M S with S diagonal, which
    moves M's own condition number by up to (max S / min S)^2 (a q in millimetres beside one in metres: 10^6)
    but not this one, so the same physics gets the same verdict in any units. Nothing is lost by it: among
    all diagonal scalings of a definite M this one is within a factor n of the best (van der Sluis 1969), and
    the LU solve's rounding acts on the scaled matrix (its backward error is small entry by entry relative
    to the scaled rows and columns)."""
    finite = torch.isfinite(hess).all(-1).all(-1)
    # a non-finite matrix is singular by fiat; an identity in its place keeps the SVD from refusing the batch
    hess = torch.where(finite[..., None, None], hess, torch.eye(hess.shape[-1], dtype=hess.dtype, device=hess.device))
    diagonal = hess.diagonal(dim1=-2, dim2=-1).abs()
    scale = torch.where(diagonal > 0, diagonal, hess.abs().amax(dim=-1))
    scale = torch.where(scale > 0, scale, torch.ones_like(scale)).rsqrt()
    values = torch.linalg.svdvals(hess * scale[..., :, None] * scale[..., None, :])
    cond = (values[..., 0] / values[..., -1]).nan_to_num(nan=float("inf"))       # 0 / 0: a zero matrix
    return torch.where(finite, cond, torch.full_like(cond, float("inf")))


def singular_condition(n: int, dtype: torch.dtype) -> float:
    """The condition number ``1 / (n eps)`` from which an n x n d2L/dqdot2 in ``dtype`` is singular to working
    precision: the LU solve's backward error is about n eps of the matrix's norm, so a smallest singular
    value under n eps of the largest is within the solve's own rounding of 0 and the equations no longer
    determine qddot (``numpy.linalg.matrix_rank``'s default tolerance). A singular M whose entries are rounded
    (a rank-deficient L differentiated twice) lands under it: its computed ratio is about eps (measured at
    most 0.8 eps over 1000 states of n = 2 and less at 3 and 5, in float32 and float64)."""
    return 1.0 / (n * torch.finfo(dtype).eps)


class SingularLagrangianError(DivergenceError, ValueError):
    """d2L/dqdot2 is singular (or too ill-conditioned to solve) at the ``states`` (row indices) named.

    A ``DivergenceError`` too, so code that reports failed rollouts by name reports this one."""

    def __init__(self, message: str, states=()):
        super().__init__(message, states)
        self.states = list(states)


class LagrangianNN(StateCheckedModel):
    """L(q, qdot), an ``hnn.MLP`` of ``[q, qdot]`` (or ``[cos q, sin q, qdot]`` with ``periodic``) to one value.

    Args:
        input_dim: 2n, the width of z = [q, qdot].
        hidden_dim, nonlinearity: of the MLP (smooth activations only: the field differentiates L twice).
        periodic: q are angles (the network sees cos q, sin q; LNN's code wraps q mod 2 pi instead).
        solve: ``'solve'`` (a ``SingularLagrangianError`` where d2L/dqdot2 is singular) or ``'pinv'`` (the
            LNN authors' pseudo-inverse there; ``pinv_states`` counts the states it took).
    """
    coordinates = "velocity"
    takes = {"cartesian": "positions and velocities of bodies: L(x, xdot) of any state [q, qdot]"}
    conservative = True

    def __init__(self, input_dim: int, hidden_dim: int = RunSettings.hidden_dim,
                 nonlinearity: str = RunSettings.nonlinearity, periodic: bool = False,
                 solve: str = "solve"):
        super().__init__()
        if solve not in LNN_SOLVES:
            raise ValueError(f"solve={solve!r}: choose one of {', '.join(LNN_SOLVES)}")
        self.n = check_width(input_dim, "LagrangianNN")
        self.input_dim, self.periodic, self.solve = input_dim, bool(periodic), solve
        self.pinv_states = 0        # states whose qddot came from the pseudo-inverse (solve='pinv'), every call
        self.net = MLP(3 * self.n if periodic else input_dim, hidden_dim, 1, nonlinearity)

    def lagrangian_at(self, q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """L at one state, ``(n,)``, ``(n,)`` -> ``()``: the network; override it to plug in a known L."""
        return self.net(torch.cat([embed_angles(q[None], self.periodic), v[None]], dim=1))[0, 0]

    def lagrangian(self, z: torch.Tensor) -> torch.Tensor:
        """L(q, qdot), ``(batch, 2n)`` -> ``(batch,)``."""
        self._check_input(z)
        return vmap(self.lagrangian_at)(z[:, :self.n], z[:, self.n:])

    def energy(self, z: torch.Tensor) -> torch.Tensor:
        """E = qdot . dL/dqdot - L, ``(batch, 2n)`` -> ``(batch,)``; differentiable in ``z`` and the weights."""
        self._check_input(z)
        with torch.enable_grad():
            z_in = z if z.requires_grad else z.detach().requires_grad_(True)
            L = self.lagrangian(z_in)
            dL = torch.autograd.grad(L.sum(), z_in, create_graph=True)[0]
        return (z[:, self.n:] * dL[:, self.n:]).sum(1) - L

    def hamiltonian(self, z: torch.Tensor) -> torch.Tensor:
        """The conserved energy E(q, qdot) (``energy``), ``(batch,)``: H in velocity coordinates."""
        return self.energy(z)

    @property
    def field(self):
        # E is conserved, but the flow is not S grad E in [q, qdot]: no solver may step it as an H's
        return self.time_derivative

    def acceleration(self, z: torch.Tensor) -> torch.Tensor:
        """qddot from the Euler-Lagrange equations, ``(batch, 2n)`` -> ``(batch, n)``; SingularLagrangianError
        where d2L/dqdot2 cannot be solved."""
        self._check_input(z)
        n, v = self.n, z[:, self.n:]
        # rows of different states never mix, so each derivative of the batch's summed L is every
        # state's own; the rows need a graph of their own only when the caller trains through them
        keep = torch.is_grad_enabled()
        if in_model_axis():         # under vmap over models (hnn.trainers.vmap): torch.func's derivatives
            dL_of = torch.func.grad(lambda zz: self.lagrangian(zz).sum())
            dL = dL_of(z)
            rows = torch.func.jacrev(lambda zz: dL_of(zz)[:, n:].sum(0))(z).movedim(0, 1)
        else:
            with torch.enable_grad():
                z_in = z if z.requires_grad else z.detach().requires_grad_(True)
                dL = torch.autograd.grad(self.lagrangian(z_in).sum(), z_in, create_graph=True)[0]     # (batch, 2n)
                rows = torch.stack([torch.autograd.grad(dL[:, n + i].sum(), z_in, create_graph=keep,
                                                        retain_graph=True)[0]
                                    for i in range(n)], dim=1)                    # (batch, n, 2n): d(dL/dqdot_i)/dz
        if not keep:
            dL, rows = dL.detach(), rows.detach()
        hess_vv, mixed = rows[:, :, n:], rows[:, :, :n]                          # mixed[b, i, j] = d2L/dqdot_i dq_j
        rhs = dL[:, :n] - (mixed @ v[..., None])[..., 0]
        if self.solve == "pinv":
            return self._pseudo_solve(hess_vv, rhs)
        qddot, info = torch.linalg.solve_ex(hess_vv, rhs[..., None])
        qddot = qddot[..., 0]
        if in_model_axis():         # vmap cannot branch on a value: a singular model's loss is not finite
            return qddot
        with torch.no_grad():
            cond = equilibrated_condition(hess_vv.detach())
            bad = (info != 0) | ~(cond < singular_condition(n, z.dtype)) | ~torch.isfinite(qddot).all(1)
        if bad.any():
            rows = torch.nonzero(bad).flatten().tolist()
            shown = "; ".join(f"#{i} [q, qdot] = {[round(float(c), 4) for c in z[i].detach()]} (cond {float(cond[i]):.3g})"
                              for i in rows[:5])
            raise SingularLagrangianError(
                f"LagrangianNN: d2L/dqdot2 is singular at {len(rows)} states, where the Euler-Lagrange equations do "
                f"not determine qddot: {shown}. A learned L needs a nondegenerate kinetic term there: train longer "
                "or on states nearer these, or choose --model mechanical (its mass matrix is positive definite by "
                "construction)", rows)
        return qddot

    def time_derivative(self, z: torch.Tensor, t=None) -> torch.Tensor:
        """``dz/dt = (qdot, qddot)``, ``(batch, 2n)``; a graph for training only in grad mode."""
        return torch.cat([z[:, self.n:], self.acceleration(z)], dim=1)

    def _pseudo_solve(self, hess_vv: torch.Tensor, rhs: torch.Tensor) -> torch.Tensor:
        """qddot ``(batch, n)`` = pinv(d2L/dqdot2) rhs, the LNN authors' solve: the pseudo-inverse drops the
        singular values below ``10 n eps`` of the largest (JAX's default cutoff), so where none lies below it
        it is the inverse, and there the (cheaper, same to rounding) plain solve is taken. The states where
        one does are counted in ``pinv_states``."""
        rtol = 10 * self.n * torch.finfo(hess_vv.dtype).eps
        if in_model_axis():         # vmap cannot pick states by a value: the pseudo-inverse at every state
            return (torch.linalg.pinv(hess_vv, rtol=rtol, hermitian=True) @ rhs[..., None])[..., 0]
        with torch.no_grad():
            finite = torch.isfinite(hess_vv.detach()).all(-1).all(-1)
            if not finite.all():        # a non-finite L, which the SVDs below would refuse with their own error
                raise _not_finite(torch.nonzero(~finite).flatten().tolist())
            cond = torch.linalg.cond(hess_vv.detach())
            cut = ~torch.isfinite(cond) | (cond * rtol > 1)
        # the plain solve where the inverse exists; an identity in place of the others keeps its graph finite
        eye = torch.eye(self.n, dtype=hess_vv.dtype, device=hess_vv.device)
        qddot = torch.linalg.solve(torch.where(cut[:, None, None], eye, hess_vv), rhs[..., None])[..., 0]
        if cut.any():
            at = torch.nonzero(cut).flatten()
            pinv = torch.linalg.pinv(hess_vv[at], rtol=rtol, hermitian=True)
            qddot = qddot.index_put((at,), (pinv @ rhs[at][..., None])[..., 0])
            self.pinv_states += len(at)
        bad = ~torch.isfinite(qddot.detach()).all(1)
        if bad.any():       # a non-finite L: no solve determines qddot
            raise _not_finite(torch.nonzero(bad).flatten().tolist())
        return qddot


def _not_finite(rows: list[int]) -> SingularLagrangianError:
    return SingularLagrangianError(f"LagrangianNN: d2L/dqdot2 or dL/dq is not finite at {len(rows)} states "
                                   f"(#{rows[0]} first), so no solve determines qddot there", rows)
