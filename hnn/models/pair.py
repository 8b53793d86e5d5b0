"""The pair kind: H = sum_i |p_i|^2 / (2 m_i) + sum_{i<j} V(|q_i - q_j|) (+ sum_i U(q_i) where the scene has a field).

One learned function V of one distance stands for every pair, so the model is invariant under translation,
rotation and the exchange of identical bodies by construction, and one set of weights reads any number of
bodies N (the state's width 2 N dim tells N; ``hnn.bodies.Bodies`` tells the order). Masses are learned, one
per species (one for bodies that are all alike). H is separable, T(p) + V(q): explicit leapfrog and
yoshida4 are symplectic for the learned model.

The pair geometry (``pair_index``, ``find_pairs``, ``inside_cutoff``, ``separations``, ``pair_gradient``) is
public: the least-squares pair fit (``hnn.fits.radial``) and the scenes' true forces read the same. A step costs
O(pairs): N(N-1)/2 for ``pairs='all'`` (gravity), N - 1 for ``pairs='neighbours'`` (neighbours along a chain of
springs), the pairs closer than r_c for ``pairs='cutoff'`` (a Lennard-Jones cluster), found at each call by a
cell list (``hnn.cells``) in O(N) at a fixed density.

``radial_slope`` (V' of distances) is public too: ``hnn.models.pair_table.TabulatedPair`` tabulates a fitted V
from it, for rollouts at about the true forces' cost a step.

With a cutoff the model assumes, as the scene's truth does, the truncated and shifted potential: each pair
adds V(r) - V(r_c) below r_c and nothing beyond, so H is continuous in the positions and its force jumps by
V'(r_c) where a pair crosses r_c. The learned V itself is not asked to vanish at r_c: the shift is the model's.

Shapes: states ``(batch, 2 N dim)``; positions and momenta per body ``(batch, N, dim)``; per-pair arrays
``(batch, P)``; H ``(batch,)``.
"""
from __future__ import annotations

import functools

import torch
from torch import nn

from ..bodies import Bodies
from ..cells import pairs_within
from ..interface import Model, gradient_of
from ..modes import in_model_axis
from ..settings import RunSettings
from .mlp import MLP

PAIR_BYTES = 2 ** 32     # the per-pair arrays of one field call are kept within this (4 GiB); more is refused
# V's network runs over the pairs in chunks whose activations stay within this (256 MB): a field call's memory then
# grows with the pairs' few numbers each (``_pairs``), not with the network's width, so gravity at N = 4096 (8.4
# million pairs) fits
CHUNK_BYTES = 2 ** 28
# the width of V's network that the studies train the pair kind at by Adam (analysis/bodies.py, the fits table,
# the 2-body and 3-body protocols): V reads one distance, and the 2-body and 3-body tasks' 200 (the paper's HNN's)
# trained it to a 3-body energy MSE of 0.0029 against 5.8e-6 at 64 (5 seeds each), the close encounters' 1/r
# (to 400) saturating the wider layers; a sampled pair fit's neurons stay the run's --hidden_dim
RADIAL_WIDTH = 64


class TooManyPairsError(MemoryError):
    """A field call over more pairs than ``PAIR_BYTES`` holds: the message says how much it needs and the fix."""


@functools.lru_cache(maxsize=32)
def _index(count: int, pairs: str) -> tuple[torch.Tensor, torch.Tensor]:
    if pairs == "neighbours":
        i = torch.arange(count - 1)
        return i, i + 1
    return tuple(torch.triu_indices(count, count, offset=1))


def pair_index(count: int, pairs: str = "all", device=None) -> tuple[torch.Tensor, torch.Tensor]:
    """``(i, j)`` ``(P,)`` each, i < j: every pair of ``count`` bodies (``'all'``) or neighbours along the index (``'neighbours'``)."""
    if pairs == "cutoff":
        raise ValueError("the pairs of Bodies(pairs='cutoff') depend on the positions, not only on the count: find "
                         "them with hnn.models.pair.find_pairs(q, bodies), and weigh each by inside_cutoff(r, bodies)")
    i, j = _index(count, pairs)
    return i.to(device), j.to(device)


def find_pairs(q: torch.Tensor, bodies: Bodies) -> tuple[torch.Tensor, torch.Tensor]:
    """``(i, j)`` ``(P,)`` each, i < j: the pairs of positions ``q`` ``(batch, N, dim)`` that ``bodies`` interacts.
    ``pair_index``'s for ``'all'`` and ``'neighbours'``; for ``'cutoff'``, the pairs closer than the cutoff in at
    least one state of the batch, by a cell list (``hnn.cells.pairs_within``): a state reads each pair through
    ``inside_cutoff``, which drops the ones beyond the cutoff there."""
    if bodies.pairs == "cutoff":
        i, j = pairs_within(q, bodies.cutoff)
        return i.to(q.device), j.to(q.device)
    return pair_index(q.shape[1], bodies.pairs, q.device)


def inside_cutoff(r: torch.Tensor, bodies: Bodies) -> torch.Tensor | None:
    """Which pairs of distances ``r`` ``(batch, P)`` interact in their own state ``(batch, P)`` bool: r < the cutoff
    (a NaN distance counts as inside, so that it reaches H as it does without a cutoff); None for a layout without
    a cutoff (every listed pair interacts)."""
    if bodies.pairs != "cutoff":
        return None
    return ~(r >= bodies.cutoff)


def check_pair_memory(batch: int, pairs: int, per_pair: int, itemsize: int) -> None:
    """A ``TooManyPairsError`` if ``batch`` states of ``pairs`` pairs, ``per_pair`` numbers each, pass ``PAIR_BYTES``."""
    need = batch * pairs * per_pair * itemsize
    if need > PAIR_BYTES:
        raise TooManyPairsError(
            f"{batch} states of {pairs} interacting pairs need about {need / 2 ** 30:.1f} GiB for one field call "
            f"(limit hnn.models.pair.PAIR_BYTES = {PAIR_BYTES / 2 ** 30:.0f} GiB): evaluate fewer states at once "
            "(a smaller batch), or declare a short-range scene's neighbours (Bodies(pairs='neighbours')) or cutoff "
            "(Bodies(pairs='cutoff', cutoff=r_c))")


def separations(q: torch.Tensor, i: torch.Tensor, j: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(d, r)``: d = q_i - q_j ``(batch, P, dim)`` and r = |d| ``(batch, P)`` of positions ``q`` ``(batch, N, dim)``."""
    d = q[:, i] - q[:, j]
    return d, torch.linalg.vector_norm(d, dim=-1)


def pair_gradient(dVdr: torch.Tensor, d: torch.Tensor, r: torch.Tensor, i: torch.Tensor, j: torch.Tensor,
                  count: int) -> torch.Tensor:
    """dV/dq ``(batch, N, dim)`` of V = sum over pairs of V(r): V'(r) d / r onto body i, minus it onto body j."""
    push = (dVdr / r)[..., None] * d
    out = push.new_zeros(push.shape[0], count, push.shape[2])
    return out.index_add(1, i, push).index_add(1, j, -push)


class PairHNN(Model):
    """H = sum |p_i|^2 / (2 m_s(i)) + sum_{pairs} V(r_ij) [+ sum U(q_i)], V an MLP of (r, 1/r), for ``bodies``.

    ``hidden_dim``, ``nonlinearity``: the MLPs'. ``masses(count)`` ``(count,)``: exp of a learned log-mass per
    species. The input 1/r beside r lets one MLP reach the inverse-distance tail of gravity and the walls of
    stiff potentials without learning a division."""
    conservative = True
    separable = True

    def __init__(self, bodies: Bodies, hidden_dim: int = RunSettings.hidden_dim,
                 nonlinearity: str = RunSettings.nonlinearity):
        super().__init__()
        self.bodies = Bodies.from_dict(bodies)
        self.input_dim, self.hidden_dim = self.bodies.width, hidden_dim
        self.radial_net = MLP(2, hidden_dim, 1, nonlinearity)
        self.log_mass = nn.Parameter(torch.zeros(self.bodies.num_species))
        self.external_net = MLP(self.bodies.dim, hidden_dim, 1, nonlinearity) if self.bodies.external else None

    def masses(self, count: int) -> torch.Tensor:
        """The mass of each of ``count`` bodies ``(count,)``, by its species."""
        if self.bodies.species is None:     # all alike: one mass, no labels to build at every field call
            return self.log_mass.exp().expand(count)
        labels = torch.tensor(self.bodies.labels(count), device=self.log_mass.device)
        return self.log_mass.exp()[labels]

    def radial(self, r: torch.Tensor) -> torch.Tensor:
        """V(r) of distances ``r`` (any shape), the same shape."""
        flat = r.reshape(-1, 1)
        return self.radial_net(torch.cat([flat, 1 / flat], dim=1)).reshape(r.shape)

    def _chunks(self, r: torch.Tensor) -> list[slice]:
        """The pairs of ``r`` ``(batch, P)`` in chunks whose network activations (3 x width numbers a pair and
        state) stay within ``CHUNK_BYTES``: one chunk of every pair where they fit (the lattice's 4095 neighbours
        of 4 states at width 64 do: its published numbers come from one chunk)."""
        per_pair = 3 * self.hidden_dim * r.shape[0] * r.element_size()
        size = max(1, CHUNK_BYTES // per_pair)
        return [slice(k, k + size) for k in range(0, r.shape[1], size)]

    def _pair_energy(self, r: torch.Tensor) -> torch.Tensor:
        """sum over pairs of V(r) ``(batch,)`` of distances ``r`` ``(batch, P)``, chunk by chunk; with a cutoff,
        V(r) - V(r_c) over the pairs inside it."""
        inside = inside_cutoff(r, self.bodies)
        if inside is None:
            return sum(self.radial(r[:, chunk]).sum(dim=1) for chunk in self._chunks(r))
        shift = self.radial(r.new_full((1,), self.bodies.cutoff))
        return sum(torch.where(inside[:, chunk], self.radial(r[:, chunk]) - shift, 0).sum(dim=1)
                   for chunk in self._chunks(r))

    def _closed_form_slope(self) -> bool:
        """Whether V' can come from the tanh MLP's closed-form input gradient (``MLP.input_gradient``): V is this
        model's own ``radial`` of its ``radial_net``, a plain tanh ``MLP``, outside vmap over models (where the
        closed form has no batching rule). Else autograd of ``radial``, which any network takes."""
        net = self.radial_net
        return ("radial" not in vars(self) and type(net) is MLP and net.nonlinearity_name == "tanh"
                and not in_model_axis())

    def radial_slope(self, r: torch.Tensor) -> torch.Tensor:
        """V'(r) of distances ``r`` ``(batch, P)``, the same shape. V reads (r, 1/r), so V' = dV/dr + dV/d(1/r)
        (-1/r^2). In closed form where it applies: training then backpropagates once through the hand-written
        backward (``hnn.models.tanh_mlp``) where autograd's double backward took three times the pairs' rows
        of a state's work (docs/bodies.md); the same numbers to round-off."""
        if not self._closed_form_slope():
            return gradient_of(lambda rr: self.radial(rr).sum(dim=1), r)
        flat = r.reshape(-1, 1)
        inverse = 1 / flat
        grad = self.radial_net.input_gradient(torch.cat([flat, inverse], dim=1), 0, torch.is_grad_enabled())
        return (grad[:, :1] - grad[:, 1:] * (inverse * inverse)).reshape(r.shape)

    def _pair_slope(self, r: torch.Tensor) -> torch.Tensor:
        """V'(r) ``(batch, P)``, chunk by chunk (the graph of one chunk at a time outside training); 0 for a
        pair beyond the cutoff."""
        chunks = self._chunks(r)
        slopes = [self.radial_slope(r[:, chunk]) for chunk in chunks]
        slope = slopes[0] if len(slopes) == 1 else torch.cat(slopes, dim=1)
        inside = inside_cutoff(r, self.bodies)
        return slope if inside is None else torch.where(inside, slope, 0)

    def _pairs(self, q: torch.Tensor):
        i, j = find_pairs(q, self.bodies)
        # the numbers a pair and state holds at once: r, 1/r and V'(r), and d, its gathered ends' and the push
        check_pair_memory(len(q), len(i), 3 + 3 * self.bodies.dim, q.element_size())
        return i, j

    def kinetic(self, p_half: torch.Tensor) -> torch.Tensor:
        """T ``(batch,)`` of one half ``(batch, N dim)``."""
        p = self.bodies.bodywise(p_half)
        return ((p * p).sum(dim=2) / (2 * self.masses(p.shape[1]))).sum(dim=1)

    def potential(self, q_half: torch.Tensor) -> torch.Tensor:
        """V ``(batch,)`` of one half ``(batch, N dim)``: the pairs' V(r), and U(q_i) where the scene has a field."""
        q = self.bodies.bodywise(q_half)
        i, j = self._pairs(q)
        _, r = separations(q, i, j)
        out = self._pair_energy(r)
        if self.external_net is not None:
            out = out + self.external_net(q.reshape(-1, q.shape[2])).reshape(q.shape[:2]).sum(dim=1)
        return out

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H ``(batch,)`` at ``x`` ``(batch, 2 N dim)``, any N."""
        half = self._half(x)
        return self.kinetic(x[:, half:]) + self.potential(x[:, :half])

    def kinetic_gradient(self, p_half: torch.Tensor) -> torch.Tensor:
        """dT/dp = p_i / m_i ``(batch, N dim)``."""
        p = self.bodies.bodywise(p_half)
        return self.bodies.flat(p / self.masses(p.shape[1])[:, None])

    def potential_gradient(self, q_half: torch.Tensor) -> torch.Tensor:
        """dV/dq ``(batch, N dim)``: each pair's V'(r) along its separation, O(pairs); U's gradient where present."""
        q = self.bodies.bodywise(q_half)
        i, j = self._pairs(q)
        d, r = separations(q, i, j)
        grad = pair_gradient(self._pair_slope(r), d, r, i, j, q.shape[1])
        if self.external_net is not None:
            flat = q.reshape(-1, q.shape[2])
            grad = grad + gradient_of(lambda z: self.external_net(z)[:, 0], flat).reshape(q.shape)
        return self.bodies.flat(grad)

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        """dx/dt = [dT/dp, -dV/dq] ``(batch, 2 N dim)``."""
        half = self._half(x)
        return torch.cat([self.kinetic_gradient(x[:, half:]), -self.potential_gradient(x[:, :half])], dim=1)

    def _half(self, x: torch.Tensor) -> int:
        if x.dim() != 2:
            raise ValueError(f"expected states x of shape (batch, 2 N {self.bodies.dim}), got {tuple(x.shape)}")
        self.bodies.count_of(x.shape[1])
        return x.shape[1] // 2
