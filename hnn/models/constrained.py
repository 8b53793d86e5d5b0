"""Constrained kinds: bodies in Cartesian coordinates with known rigid constraints (Finzi, Wang &
Wilson, "Simplifying Hamiltonian and Lagrangian Neural Networks via Explicit Constraints", 2020).

A task declares its ``ConstraintGraph``: n point bodies in d dimensions, tethers of body i to a
fixed point at distance l, and rigid links between bodies i and j of length l, each constraint
phi_c = |r_c|^2 - l_c^2 with r_c = x_i - x_j (or x_i - point) and its velocity form
psi_c = d(phi_c)/dt = 2 r_c . w_c (w_c = v_i - v_j, or v_i). The models learn only a potential
V(x) (an ``hnn.MLP`` on the flattened positions) and one log-mass per body (M constant, diagonal):

- ``ConstrainedHNN`` (kind ``constrained``, CHNN): state z = [x, p] (``'cartesian_canonical'``),
  H = 1/2 sum_i |p_i|^2 / m_i + V(x), and z' = P(z) J grad H with
  P = I - J D (D^T J D)^-1 D^T, D = DPhi the Jacobian ``(2nd, 2C)`` of [phi, psi] in z.
  It maps observed [x, xdot] (``'cartesian'``) through its learned masses, p_i = m_i xdot_i.
- ``ConstrainedLNN`` (kind ``constrained_lagrangian``, CLNN): state [x, v] (``'cartesian'``),
  x'' = f - M^-1 G (G^T M^-1 G)^-1 (G^T f + Gdot^T v), f = -M^-1 grad V, G = dphi/dx ``(nd, C)``.

Why they are cheap: every constraint is a distance, so D, D^T J D and the right-hand sides have
closed forms in r, w and K = A M^-1 A^T (A the constraint-body incidence, ``(C, n)``). D^T J D
is [[0, B], [-B, E]] with B = 4 (r r^T) o K (symmetric) and E = 4 K o (w r^T - r w^T), so the
2C x 2C solve is two C x C solves with B; grad V is the tanh MLP's closed-form input gradient.
On the constraints the two fields are the same ODE. Units: those of the task (metres, seconds,
kg); shapes: states ``(batch, 2 n d)``, positions flattened body after body.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

from ..interface import Model
from ..settings import RunSettings
from ..modes import in_model_axis
from .mlp import MLP
from .structured import scalar_gradient

STATE_TOLERANCE = 1e-3     # largest relative constraint violation of a start state (|phi| / l^2, |cos(r, w)|)


@dataclass(frozen=True)
class ConstraintGraph:
    """n point ``bodies`` in ``dim`` dimensions with distance constraints.

    ``tethers``: ``(body, point, length)``, body i kept at ``length`` from the fixed ``point``
    (``dim`` coordinates); ``links``: ``(i, j, length)``, bodies i and j kept ``length`` apart.
    Lengths in the task's units (metres). Bad input is one ValueError naming the fix.
    """
    bodies: int
    dim: int = 2
    tethers: tuple = ()
    links: tuple = ()

    def __post_init__(self):
        for name in ("bodies", "dim"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"a constraint graph needs {name} >= 1 (an integer), got {value!r}")
        tethers = tuple((self._body(t[0], "tether"), self._point(t[1]), self._length(t[2], f"tether of body {t[0]}"))
                        for t in self._rows(self.tethers, 3, "tethers", "(body, point, length)"))
        links = tuple((self._body(i, "link"), self._body(j, "link"), self._length(length, f"link {i}-{j}"))
                      for i, j, length in self._rows(self.links, 3, "links", "(i, j, length)"))
        for i, j, _ in links:
            if i == j:
                raise ValueError(f"link {i}-{j} joins body {i} to itself; a link needs two different bodies")
        object.__setattr__(self, "tethers", tethers)
        object.__setattr__(self, "links", links)

    @staticmethod
    def _rows(rows, width: int, name: str, form: str) -> list:
        rows = list(rows)
        if any(not isinstance(row, (tuple, list)) or len(row) != width for row in rows):
            raise ValueError(f"constraint graph {name} must be rows of {form}, got {rows!r}")
        return rows

    def _body(self, index, what: str) -> int:
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < self.bodies:
            raise ValueError(f"a {what} names body {index!r}, out of range for {self.bodies} bodies; "
                             f"bodies are numbered 0..{self.bodies - 1}")
        return index

    def _point(self, point) -> tuple[float, ...]:
        point = tuple(float(c) for c in point)
        if len(point) != self.dim or not all(math.isfinite(c) for c in point):
            raise ValueError(f"a tether's fixed point must be {self.dim} finite coordinates, got {point!r}")
        return point

    @staticmethod
    def _length(length, what: str) -> float:
        length = float(length)
        if not (length > 0 and math.isfinite(length)):
            raise ValueError(f"the {what} has length {length!r}; a rigid constraint needs a positive finite length")
        return length

    @property
    def count(self) -> int:
        """C, the number of distance constraints (each with its velocity form: 2C in all)."""
        return len(self.tethers) + len(self.links)

    def arrays(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(A (C, n), offsets (C, d), lengths (C,))``, float64: r_c = (A X)_c + offsets_c for
        positions X ``(n, d)``; a tether's row is +1 at its body and its offset -point."""
        exact = dict(dtype=torch.float64, device="cpu")     # cast to each state's dtype and device on use
        A = torch.zeros(self.count, self.bodies, **exact)
        offsets = torch.zeros(self.count, self.dim, **exact)
        for c, (body, point, _) in enumerate(self.tethers):
            A[c, body] = 1.0
            offsets[c] = -torch.tensor(point, **exact)
        for c, (i, j, _) in enumerate(self.links, start=len(self.tethers)):
            A[c, i], A[c, j] = 1.0, -1.0
        lengths = torch.tensor([row[-1] for row in self.tethers + self.links], **exact)
        return A, offsets, lengths

    def to_dict(self) -> dict:
        """JSON-ready: what a run's args.json holds as ``"constraints"``."""
        return {"bodies": self.bodies, "dim": self.dim, "tethers": [list(t[:1]) + [list(t[1]), t[2]] for t in self.tethers],
                "links": [list(link) for link in self.links]}

    @classmethod
    def from_dict(cls, values: dict) -> ConstraintGraph:
        """The graph of ``to_dict``'s output; a missing key is one ValueError."""
        if not isinstance(values, dict) or "bodies" not in values:
            raise ValueError(f"a constraint graph is a dict with 'bodies', 'dim', 'tethers', 'links', got {values!r}")
        return cls(values["bodies"], values.get("dim", 2), tuple(values.get("tethers", ())),
                   tuple(values.get("links", ())))


class _Constrained(Model):
    """What both kinds share: the graph, V(x), the log-masses and the distance algebra."""

    def __init__(self, graph: ConstraintGraph, hidden_dim: int = 256, nonlinearity: str = RunSettings.nonlinearity,
                 tolerance: float = STATE_TOLERANCE):
        super().__init__()
        if not isinstance(graph, ConstraintGraph):
            raise TypeError(f"{type(self).__name__} needs an hnn.models.constrained.ConstraintGraph, got {type(graph).__name__}")
        self.graph, self.n, self.d, self.tolerance = graph, graph.bodies, graph.dim, float(tolerance)
        self.nd = self.n * self.d
        self.input_dim = 2 * self.nd
        self.potential_net = MLP(self.nd, hidden_dim, 1, nonlinearity)
        self.log_mass = nn.Parameter(torch.zeros(self.n))
        # the graph's arrays in float64, cast once per dtype and device: buffers would be rounded to
        # float32 at build and stay rounded after .double() (a float64 run's rods off by 1e-7)
        A, offsets, lengths = graph.arrays()
        # the field works on flat rows: r = x A_d^T + offsets (batch, C d), A_d = A kron I_d
        self._exact = (A, offsets, lengths, torch.kron(A, torch.eye(self.d, dtype=A.dtype, device=A.device)), offsets.flatten())
        self._cast: dict = {}

    def _arrays(self, like: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """``(A, offsets, lengths, A_d, flat offsets)`` (``ConstraintGraph.arrays``; A_d = A kron I_d
        ``(C d, n d)``) in ``like``'s dtype and device."""
        key = (like.dtype, like.device)
        if key not in self._cast:
            self._cast[key] = tuple(a.to(dtype=like.dtype, device=like.device) for a in self._exact)
        return self._cast[key]

    def _check_input(self, z: torch.Tensor) -> None:
        if z.dim() != 2 or z.shape[1] != self.input_dim:
            raise ValueError(f"expected a state of shape (batch, {self.input_dim}) = (batch, 2 x {self.n} bodies x "
                             f"{self.d} dims), got {tuple(z.shape)}")

    def masses(self) -> torch.Tensor:
        """The learned masses ``(n,)``, positive."""
        return torch.exp(self.log_mass)

    def potential(self, x: torch.Tensor) -> torch.Tensor:
        """V(x), flattened positions ``(batch, n d)`` -> ``(batch,)``."""
        return self.potential_net(x)[:, 0]

    def potential_gradient(self, x: torch.Tensor) -> torch.Tensor:
        """grad V, ``(batch, n d)``: the tanh MLP's closed form where it applies."""
        return scalar_gradient(self.potential_net, x, torch.is_grad_enabled())

    def _relative(self, X: torch.Tensor, V: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """r = A X + offsets and w = A V, ``(batch, C, d)``, of positions and velocities ``(batch, n, d)``."""
        A, offsets = self._arrays(X)[:2]
        return A @ X + offsets, A @ V

    def _split(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Positions and velocities ``(batch, n, d)`` of a state ``(batch, 2nd)``."""
        raise NotImplementedError

    def _positions_velocities(self, z: torch.Tensor, observed: str | None) -> tuple[torch.Tensor, torch.Tensor]:
        """Positions and velocities ``(batch, n, d)`` of states in ``observed`` coordinates (None: its own)."""
        self._check_input(z)
        if observed in (None, self.coordinates):
            return self._split(z)
        self.relation(observed)
        return z[:, :self.nd].view(len(z), self.n, self.d), z[:, self.nd:].view(len(z), self.n, self.d)

    def constraints(self, z: torch.Tensor, observed: str | None = None) -> torch.Tensor:
        """[phi, psi] ``(batch, 2C)``: |r_c|^2 - l_c^2 and 2 r_c . w_c at states ``z`` ``(batch, 2nd)``
        in ``observed`` coordinates (default: the model's own)."""
        r, w = self._relative(*self._positions_velocities(z, observed))
        return torch.cat([r.pow(2).sum(-1) - self._arrays(z)[2] ** 2, 2 * (r * w).sum(-1)], dim=1)

    def violation(self, z: torch.Tensor, observed: str | None = None) -> torch.Tensor:
        """How far states ``(batch, 2nd)`` in ``observed`` coordinates (default: its own) are off the
        constraints, ``(batch,)``, unitless: the largest |phi_c| / l_c^2 and |r_c . w_c| / (l_c u), u
        the RMS speed of the row's bodies (not |w_c|: a nearly rigid pair's tiny w_c would turn float32
        round-off into a large cosine)."""
        X, V = self._positions_velocities(z, observed)
        r, w = self._relative(X, V)
        lengths = self._arrays(z)[2]
        position = (r.pow(2).sum(-1) - lengths ** 2).abs() / lengths ** 2
        speed = V.pow(2).sum(-1).mean(-1, keepdim=True).sqrt()
        velocity = (r * w).sum(-1).abs() / (lengths * speed).clamp_min(torch.finfo(z.dtype).tiny)
        return torch.cat([position, velocity], dim=1).amax(dim=1) if self.graph.count else z.new_zeros(len(z))

    def check_state(self, z: torch.Tensor, observed: str | None = None) -> None:
        """ValueError if a state ``(batch, 2nd)`` in ``observed`` coordinates (default: its own) is off
        the constraints by more than ``tolerance``; not checked under vmap over models (``hnn.modes.model_axis``),
        where the group's data were checked by each model's lone path."""
        if in_model_axis():
            return
        with torch.no_grad():       # a check on the data: no graph for training to carry
            off = self.violation(z, observed)
        if len(off) and float(off.max()) > self.tolerance:
            row = int(off.argmax())
            raise ValueError(f"state row {row} is off the constraints by {float(off[row]):.3g} (relative; tolerance "
                             f"{self.tolerance:g}): start from states on the task's constraints (project them first)")

    def state_from(self, z: torch.Tensor, observed: str) -> torch.Tensor:
        """The model's own state for observed states on the constraints (checked: ``check_state``)."""
        self.check_state(z, observed)
        return super().state_from(z, observed)

    def _flat(self, x: torch.Tensor, v: torch.Tensor, momenta: bool = False) -> tuple:
        """What both fields read, on flat rows ``(batch, n d)`` of positions and velocities (with
        ``momenta``: momenta, turned into velocities by M^-1 here): ``(M^-1 per coordinate (n d,), A_d, v, r, w, K (C, C),
        B/4 = (r r^T) o K (batch, C, C))``, r and w ``(batch, C, d)``."""
        A, _, _, A_d, offsets = self._arrays(x)
        inverse_mass = torch.exp(-self.log_mass)
        K = (A * inverse_mass) @ A.T
        scale = inverse_mass.repeat_interleave(self.d)
        v = scale * v if momenta else v
        r = torch.addmm(offsets, x, A_d.T).view(len(x), -1, self.d)
        w = (v @ A_d.T).view_as(r)
        return scale, A_d, v, r, w, K, (r @ r.transpose(1, 2)) * K

    def _spread(self, per_constraint: torch.Tensor, A_d: torch.Tensor) -> torch.Tensor:
        """A^T applied to per-constraint vectors ``(batch, C, d)``: their sum on each body, ``(batch, n d)``."""
        return per_constraint.flatten(1) @ A_d


class ConstrainedHNN(_Constrained):
    """CHNN: H(x, p) = 1/2 sum_i |p_i|^2 / m_i + V(x) on z = [x, p] ``(batch, 2nd)``, z' = P(z) J grad H.

    Args:
        graph: the task's ``ConstraintGraph``.
        hidden_dim, nonlinearity: V's ``hnn.MLP`` (theirs: 3 x 256 tanh; ours two hidden layers).
        tolerance: the largest relative violation of a start state (``check_state``).
    """
    coordinates = "cartesian_canonical"
    maps = ("cartesian",)
    conservative = True

    def _split(self, z):
        X = z[:, :self.nd].view(len(z), self.n, self.d)
        return X, z[:, self.nd:].view_as(X) * torch.exp(-self.log_mass)[:, None]

    def hamiltonian(self, z: torch.Tensor) -> torch.Tensor:
        """H ``(batch,)`` at z = [x, p] ``(batch, 2nd)``."""
        self._check_input(z)
        p = z[:, self.nd:].view(len(z), self.n, self.d)
        return 0.5 * (p.pow(2).sum(-1) * torch.exp(-self.log_mass)).sum(1) + self.potential(z[:, :self.nd])

    def constraint_jacobian(self, z: torch.Tensor) -> torch.Tensor:
        """D = DPhi ``(batch, 2nd, 2C)``: the gradients in z of [phi, psi] (closed form; dense, for
        tests and inspection; the field never builds it)."""
        self._check_input(z)
        X, V = self._split(z)
        r, w = self._relative(X, V)
        A, inverse_mass = self._arrays(z)[0], torch.exp(-self.log_mass)
        # d phi_c / d x_k = 2 A_ck r_c; d psi_c / d x_k = 2 A_ck w_c; d psi_c / d p_k = 2 A_ck r_c / m_k
        spread = A.T[None, :, :, None]                                       # (1, n, C, 1)
        d_phi_x = 2 * spread * r[:, None]                                    # (batch, n, C, d)
        d_psi_x = 2 * spread * w[:, None]
        d_psi_p = d_phi_x * inverse_mass[None, :, None, None]

        def flat(block):                                                     # (batch, n, C, d) -> (batch, nd, C)
            return block.transpose(2, 3).reshape(len(z), self.nd, -1)
        top = torch.cat([flat(d_phi_x), flat(d_psi_x)], dim=2)
        bottom = torch.cat([torch.zeros_like(flat(d_phi_x)), flat(d_psi_p)], dim=2)
        return torch.cat([top, bottom], dim=1)

    def projection(self, z: torch.Tensor) -> torch.Tensor:
        """P(z) = I - J D (D^T J D)^-1 D^T ``(batch, 2nd, 2nd)``, dense (tests, inspection)."""
        D = self.constraint_jacobian(z)
        JD = torch.cat([D[:, self.nd:], -D[:, :self.nd]], dim=1)
        eye = torch.eye(self.input_dim, dtype=z.dtype, device=z.device)
        return eye - JD @ torch.linalg.solve(D.transpose(1, 2) @ JD, D.transpose(1, 2))

    def time_derivative(self, z: torch.Tensor, t=None) -> torch.Tensor:
        """z' = P(z) J grad H ``(batch, 2nd)`` by the block closed form (module docstring); a graph
        for training only in grad mode."""
        self._check_input(z)
        x = z[:, :self.nd]
        grad_v = self.potential_gradient(x)
        if not self.graph.count:
            return torch.cat([z[:, self.nd:] * torch.exp(-self.log_mass).repeat_interleave(self.d), -grad_v], dim=1)
        inverse_mass, A_d, v, r, w, K, B4 = self._flat(x, z[:, self.nd:], momenta=True)
        # with B = 4 B4 and D^T J grad H = (2 r.w, 2 |w|^2 - 2 r.(A M^-1 grad V)), the multipliers
        # scaled by 2 are sigma = B4^-1 (r.w) and tau = B4^-1 (E sigma / 4 - |w|^2 + r.(A M^-1 grad V)),
        # E sigma / 4 = w_c . sum_e K_ce sigma_e r_e - r_c . sum_e K_ce sigma_e w_e (E never formed)
        pull = ((grad_v * inverse_mass) @ A_d.T).view_as(r)
        # two solves, not one LU factor and two lu_solves: the factor's own backward cost more than both
        sigma = torch.linalg.solve(B4, (r * w).sum(-1, keepdim=True))               # (batch, C, 1)
        rw = (K * sigma.transpose(1, 2)) @ torch.cat([r, w], dim=2)
        tau = torch.linalg.solve(B4, (w * (rw[..., :self.d] - w) + r * (pull - rw[..., self.d:])).sum(-1, keepdim=True))
        dx = v - inverse_mass * self._spread(sigma * r, A_d)
        dp = self._spread(tau * r + sigma * w, A_d) - grad_v
        return torch.cat([dx, dp], dim=1)

    def state_from_observed(self, z: torch.Tensor) -> torch.Tensor:
        """[x, p] with p_i = m_i xdot_i, from observed [x, xdot] ``(batch, 2nd)``."""
        self._check_input(z)
        p = z[:, self.nd:].view(len(z), self.n, self.d) * self.masses()[:, None]
        return torch.cat([z[:, :self.nd], p.flatten(1)], dim=1)

    def observed_from_state(self, x: torch.Tensor) -> torch.Tensor:
        """[x, xdot] with xdot_i = p_i / m_i, from [x, p] ``(batch, 2nd)``."""
        self._check_input(x)
        return torch.cat([x[:, :self.nd], self._split(x)[1].flatten(1)], dim=1)

    def observed_time_derivative(self, z: torch.Tensor) -> torch.Tensor:
        """d/dt of observed [x, xdot] ``(batch, 2nd)`` along the flow: (x', M^-1 p'), M constant."""
        dz = self.time_derivative(self.state_from_observed(z))
        dv = dz[:, self.nd:].view(len(z), self.n, self.d) * torch.exp(-self.log_mass)[:, None]
        return torch.cat([dz[:, :self.nd], dv.flatten(1)], dim=1)


class ConstrainedLNN(_Constrained):
    """CLNN: L = 1/2 sum_i m_i |v_i|^2 - V(x) on z = [x, v] ``(batch, 2nd)``; x'' by the constrained
    Euler-Lagrange equations (module docstring). Its energy is conserved on the constraints only,
    so it declares no H (``conservative = False``).

    Args: as ``ConstrainedHNN``.
    """
    coordinates = "cartesian"

    def _split(self, z):
        X = z[:, :self.nd].view(len(z), self.n, self.d)
        return X, z[:, self.nd:].view_as(X)

    def energy(self, z: torch.Tensor) -> torch.Tensor:
        """1/2 sum_i m_i |v_i|^2 + V(x), ``(batch,)``: conserved along the flow on the constraints."""
        self._check_input(z)
        _, V = self._split(z)
        return 0.5 * (V.pow(2).sum(-1) * self.masses()).sum(1) + self.potential(z[:, :self.nd])

    def time_derivative(self, z: torch.Tensor, t=None) -> torch.Tensor:
        """z' = (v, x'') ``(batch, 2nd)``; a graph for training only in grad mode."""
        self._check_input(z)
        x, v = z[:, :self.nd], z[:, self.nd:]
        grad_v = self.potential_gradient(x)
        if not self.graph.count:
            return torch.cat([v, -torch.exp(-self.log_mass).repeat_interleave(self.d) * grad_v], dim=1)
        inverse_mass, A_d, _, r, w, _, B4 = self._flat(x, v)
        f = -inverse_mass * grad_v                                   # the free acceleration
        # mu = (G^T M^-1 G)^-1 (G^T f + Gdot^T v) with G^T M^-1 G = 4 B4, G^T f = 2 r.(A f),
        # Gdot^T v = 2 |w|^2; the force on the bodies A^T (2 mu r) = A^T (nu r), nu = B4^-1 (r.(A f) + |w|^2)
        nu = torch.linalg.solve(B4, (r * (f @ A_d.T).view_as(r) + w * w).sum(-1, keepdim=True))
        return torch.cat([v, f - inverse_mass * self._spread(nu * r, A_d)], dim=1)
