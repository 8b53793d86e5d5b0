"""The pair kind fitted by least squares: V(r) = sum_k c_k phi_k(r) over radial features, 1/m per species,
each found by one linear solve of dx/dt (``hnn.fits.fitting.solve``), as the other fits are.

H = sum_i |p_i|^2 a_s(i) / 2 + sum over pairs sum_k c_k phi_k(r_ij) (+ a constant). dq_i/dt = a_s(i) p_i is
linear in the inverse masses a, and dp_i/dt = -sum_k c_k sum_j phi_k'(r_ij) (q_i - q_j) / r_ij is linear in c:
two problems, as the separable fit's T and V. The features:

- ``RadialLibrary``: terms written out (``RADIAL_TERMS``: r^k and r^-k for k = 1..3, exp(-r), the
  Lennard-Jones r^-6 and r^-12; and where the scene is Plummer-softened, its softening e > 0 the task's
  ``softening`` setting, ``1/sqrt(r^2 + e^2)`` for that e), thresholded as the library fit is, so V prints as an
  equation of r;
- sampled radial neurons, tanh(w r + b) (``hnn.fits.features.TanhFeatures`` on one input, r), drawn by
  SWIM from pairs of observed distances or by ELM (``--fit swim``, ``--fit elm``).

The pair geometry is the pair kind's (``hnn.models.pair``); the layout the task's (``hnn.bodies.Bodies``). With a
cutoff (``Bodies(pairs='cutoff')``, a Lennard-Jones cluster's r_c) the fit reads what the pair kind and the scene's
truth read: the pairs closer than r_c (a cell list at each call), each adding V(r) - V(r_c) and none beyond, so a
pair outside r_c has no slope in the design, none in the field and no distance among those sampled neurons are
drawn from; the library's coefficients are V's own, and its equation says the shift.
A field call runs the features over the pairs in chunks (``CHUNK_BYTES``, as the pair kind's network does), so
its memory grows with the pairs' few numbers each, not with the features' width; past ``PAIR_LIST_BODIES`` bodies
every pair interacting, it runs block by block of bodies against every body (``BLOCK_BYTES`` a block, as the true
gravity of ``hnn.orbits.nbody`` does: no per-pair index gathers and scatters), so a fit rolls out gravity at
N = 4096 (8.4 million pairs a state). States ``(rows, 2 N dim)``, float64.
"""
from __future__ import annotations

import math

import torch
from torch import nn

from ..bodies import Bodies
from ..interface import Model
from ..modes import in_model_axis
from ..models.pair import CHUNK_BYTES, check_pair_memory, find_pairs, inside_cutoff, pair_gradient, separations
from .base import Features
from .models import Part

# name -> (V's term, its derivative d/dr): the radial library
RADIAL_TERMS = {
    "r": (lambda r: r, lambda r: torch.ones_like(r)),
    "r^2": (lambda r: r ** 2, lambda r: 2 * r),
    "r^3": (lambda r: r ** 3, lambda r: 3 * r ** 2),
    "1/r": (lambda r: 1 / r, lambda r: -1 / r ** 2),
    "1/r^2": (lambda r: r ** -2, lambda r: -2 * r ** -3),
    "1/r^3": (lambda r: r ** -3, lambda r: -3 * r ** -4),
    "exp(-r)": (lambda r: torch.exp(-r), lambda r: -torch.exp(-r)),
    "1/r^6": (lambda r: r ** -6, lambda r: -6 * r ** -7),
    "1/r^12": (lambda r: r ** -12, lambda r: -12 * r ** -13),
}
# numbers a pair and state holds at once in a field call: r, V'(r) (or V), and d, its gathered ends' and the push
# (per dimension); the features' own width lives only a chunk at a time (``FittedPair._chunked``)
_FIELD_NUMBERS = 3
_FIELD_NUMBERS_PER_DIM = 3
# features' numbers a pair row holds in a chunk: their values, their slopes and a temporary (tanh's w r + b)
_CHUNK_WIDTHS = 3
# up to this many bodies a field call of every pair sums over the pair list (every published fit's scene: 2, 3 and
# 8 bodies, and a lattice's neighbours at any N); past it, over blocks of bodies against every body, each pair twice
# but with no index scatter: gravity at N = 4096, library, 2 states, one thread: 1.2 s a call against 7.5 s over the
# pair list (loaded 2-core box)
PAIR_LIST_BODIES = 64
# a block's arrays stay within this (4 MB: in cache, hnn.orbits.nbody's BLOCK_BYTES measured the same)
BLOCK_BYTES = 2 ** 22


def softened_term(softening: float) -> tuple[str, tuple]:
    """``(name, (value, d/dr))`` of Plummer's softened inverse distance 1/sqrt(r^2 + e^2) at e = ``softening``
    (> 0): the term whose coefficient -G m_i m_j is a softened gravity's pair potential."""
    e2 = softening ** 2

    def slope(r):       # -r (r^2 + e^2)^-3/2 by rsqrt and products: a power of -1.5 cost 3x their time
        s = (r * r + e2).rsqrt()
        return -r * s * s * s
    return f"1/sqrt(r^2 + {softening:g}^2)", (lambda r: (r * r + e2).rsqrt(), slope)


class RadialLibrary(Features):
    """The radial terms ``RADIAL_TERMS``, then, at a ``softening`` e > 0 (a Plummer-softened scene's length, the
    units of r), the softened inverse distance 1/sqrt(r^2 + e^2) (``softened_term``): values and d/dr
    ``(rows, terms)`` at distances ``r`` ``(rows, 1)``; the ``library`` fit's features of the ``radial`` form (a
    pair potential V(r)), printed as its formula. At e = 0 the terms are ``RADIAL_TERMS`` alone, in their order."""
    forms = ("radial",)
    formula = True
    subset = True

    def __init__(self, softening: float = 0.0):
        super().__init__()
        if not (isinstance(softening, (int, float)) and math.isfinite(softening) and softening >= 0):
            raise ValueError(f"the radial library's softening is a Plummer length e >= 0 (0: none), got {softening!r}: "
                             "pass the scene's --softening")
        self.softening = float(softening)
        self.terms = dict(RADIAL_TERMS)
        if self.softening > 0:
            name, term = softened_term(self.softening)
            self.terms[name] = term
        self.width, self.in_dim = len(self.terms), 1

    @classmethod
    def make(cls, spec, form: str, in_dim: int) -> RadialLibrary:
        """Every term of ``RADIAL_TERMS``, and the softened one at the scene's softening (``spec.softening``, the
        task's setting: 0 where the task declares none)."""
        return cls(spec.softening)

    def forward(self, r: torch.Tensor, keep: torch.Tensor | None = None) -> torch.Tensor:
        """phi ``(rows, terms)`` at ``r`` ``(rows, 1)`` (``keep``: a boolean mask of the terms, only those)."""
        terms = list(self.terms.values())
        if keep is not None:
            terms = [term for term, kept in zip(terms, keep.tolist()) if kept]
        return torch.cat([value(r) for value, _ in terms], dim=1) if terms else r.new_zeros(len(r), 0)

    def jacobian(self, r: torch.Tensor) -> torch.Tensor:
        """d phi_k / dr ``(rows, terms, 1)``."""
        return torch.cat([slope(r) for _, slope in self.terms.values()], dim=1)[:, :, None]

    def gradient(self, r: torch.Tensor, coef: torch.Tensor) -> torch.Tensor:
        """d/dr of phi(r) . coef ``(rows, 1)``: the terms of nonzero ``coef`` alone, in order (a thresholded fit
        keeps one or two of ten: a field call at N = 4096 then costs what the true forces' do, and a far term
        that overflows, 1/r^12 at a close pair, never meets its zero as inf * 0)."""
        out = torch.zeros_like(r)
        for c, (_, slope) in zip(coef.tolist(), self.terms.values()):
            if c != 0:
                out = out + c * slope(r)
        return out

    def names(self, columns: list[str] | None = None) -> list[str]:
        return list(self.terms)


def _derivative(features: Features, r: torch.Tensor) -> torch.Tensor:
    """d phi_k / dr ``(rows, width)`` at ``r`` ``(rows, 1)``: any radial feature set's one column of its Jacobian."""
    return features.jacobian(r)[:, :, 0]


def _frozen(*shape) -> nn.Parameter:
    return nn.Parameter(torch.zeros(*shape, dtype=torch.float64), requires_grad=False)


class FittedPair(Model):
    """The pair kind's fitted model: V(r) = phi(r) . coef over ``features`` (``RadialLibrary`` or a
    ``TanhFeatures`` of one input), inverse masses ``inverse_mass`` ``(species,)``, for ``bodies``."""
    conservative = True
    separable = True

    kind = "pairwise"
    reads_bodies = True         # x's columns as the bodies' (``bodies``), any count of them

    def __init__(self, bodies: Bodies, features: Features):
        super().__init__()
        self.bodies = Bodies.from_dict(bodies)
        if self.bodies.external:
            raise ValueError("the least-squares pair fit has no one-body field U(q_i): fit this scene with "
                             "--fit adam, or declare Bodies(external=False)")
        self.input_dim = self.bodies.width
        self.features = features
        self.coef, self.offset = _frozen(features.width), _frozen(())
        self.inverse_mass = _frozen(self.bodies.num_species)

    @classmethod
    def from_spec(cls, spec, features) -> FittedPair:
        """The untrained model of ``spec`` (kind ``pairwise``, its ``bodies`` the task's layout) over
        ``features('radial', 1)`` (the fit row's radial features); zeros until solved."""
        if spec.bodies is None:
            raise ValueError("the pairwise kind reads the state as bodies and needs their layout (ModelSpec.bodies): "
                             "a task declares it (its Config's BODIES = hnn.bodies.Bodies(...)), "
                             "hnn.fit_least_squares takes it as bodies=hnn.bodies.Bodies(count=N, dim=d)")
        return cls(spec.bodies, features("radial", 1))

    def _geometry(self, q_half: torch.Tensor, design: bool = False):
        """``(q, i, j, d, r, inside)`` of positions ``q_half``: the interacting pairs (``find_pairs``: with a cutoff,
        those closer than it in some state) and which of them are inside the cutoff in each state ``(batch, P)``
        bool (None without a cutoff: every listed pair); refused (``TooManyPairsError``) past ``PAIR_BYTES`` of a
        field call's per-pair numbers, or, for a fit's ``design``, of its columns (every feature's slope at every
        pair)."""
        q = self.bodies.bodywise(q_half)
        i, j = find_pairs(q, self.bodies)
        per_pair = (2 * self.features.width + 2 * self.bodies.dim if design else
                    _FIELD_NUMBERS + _FIELD_NUMBERS_PER_DIM * self.bodies.dim)
        check_pair_memory(len(q), len(i), per_pair, q.element_size())
        d, r = separations(q, i, j)
        return q, i, j, d, r, inside_cutoff(r, self.bodies)

    def _inverse_masses(self, count: int) -> torch.Tensor:
        if self.bodies.species is None:     # all alike: one mass, no labels to build at every field call
            return self.inverse_mass.expand(count)
        return self.inverse_mass[torch.tensor(self.bodies.labels(count))]

    def _chunked(self, r: torch.Tensor, column) -> torch.Tensor:
        """``column(z)`` ``(rows,)`` of distances ``z`` ``(rows, 1)`` at every entry of ``r`` (any shape), the same
        shape, over chunks of entries whose features (``_CHUNK_WIDTHS`` x width numbers each) stay within
        ``CHUNK_BYTES``: one chunk where they fit (the lattice's published rollouts are one chunk)."""
        flat = r.reshape(-1, 1)
        size = max(1, CHUNK_BYTES // (_CHUNK_WIDTHS * self.features.width * flat.element_size()))
        if size >= len(flat):
            return column(flat).reshape(r.shape)
        return torch.cat([column(flat[k:k + size]) for k in range(0, len(flat), size)]).reshape(r.shape)

    def _slope_width(self) -> int:
        """The features a slope evaluates at once: a library's nonzero terms alone (``Features.subset``; at least
        one), else every feature; the blocks of ``_blocked_gradient`` are sized by it (gravity's one softened term
        of ten: blocks 10x the rows, a tenth of the calls)."""
        if self.features.subset and not in_model_axis():
            return max(1, int((self.coef != 0).sum()))
        return self.features.width

    def radial(self, r: torch.Tensor) -> torch.Tensor:
        """V(r) of distances ``r`` (any shape), the same shape (without the constant); a library's nonzero terms
        alone (``Features.subset``)."""
        if self.features.subset:
            keep = self.coef != 0
            return self._chunked(r, lambda z: self.features(z, keep) @ self.coef[keep])
        return self._chunked(r, lambda z: self.features(z) @ self.coef)

    def radial_slope(self, r: torch.Tensor) -> torch.Tensor:
        """V'(r) of distances ``r`` (any shape), the same shape; a library's nonzero terms alone (its ``gradient``),
        sampled neurons' through their Jacobian, as the fit's design reads them."""
        if self.features.subset:
            return self._chunked(r, lambda z: self.features.gradient(z, self.coef)[:, 0])
        return self._chunked(r, lambda z: _derivative(self.features, z) @ self.coef)

    def kinetic(self, p_half: torch.Tensor) -> torch.Tensor:
        p = self.bodies.bodywise(p_half)
        return ((p * p).sum(dim=2) * self._inverse_masses(p.shape[1]) / 2).sum(dim=1)

    def potential(self, q_half: torch.Tensor) -> torch.Tensor:
        """sum over pairs of V(r) ``(batch,)``; with a cutoff, V(r) - V(r_c) over the pairs inside it."""
        *_, r, inside = self._geometry(q_half)
        if inside is None:
            return self.radial(r).sum(dim=1)
        shift = self.radial(r.new_full((1,), self.bodies.cutoff))
        return torch.where(inside, self.radial(r) - shift, 0).sum(dim=1)

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H ``(rows,)`` at ``x`` ``(rows, 2 N dim)``, any N."""
        half = x.shape[1] // 2
        return self.kinetic(x[:, half:]) + self.potential(x[:, :half]) + self.offset

    def kinetic_gradient(self, p_half: torch.Tensor) -> torch.Tensor:
        p = self.bodies.bodywise(p_half)
        return self.bodies.flat(p * self._inverse_masses(p.shape[1])[:, None])

    def potential_gradient(self, q_half: torch.Tensor) -> torch.Tensor:
        if self.bodies.pairs == "all" and q_half.shape[1] // self.bodies.dim > PAIR_LIST_BODIES:
            return self.bodies.flat(self._blocked_gradient(self.bodies.bodywise(q_half)))
        q, i, j, d, r, inside = self._geometry(q_half)
        slope = self.radial_slope(r)
        if inside is not None:      # a pair beyond the cutoff pulls nothing
            slope = torch.where(inside, slope, 0)
        return self.bodies.flat(pair_gradient(slope, d, r, i, j, q.shape[1]))

    def _blocked_gradient(self, q: torch.Tensor) -> torch.Tensor:
        """dV/dq ``(batch, N, dim)`` of positions ``q`` ``(batch, N, dim)``, every pair interacting: for each block
        of bodies i, sum_j V'(r_ij) (q_i - q_j) / r_ij over every body j != i, blocks within ``BLOCK_BYTES``."""
        batch, count, dim = q.shape
        # a body's row against every body holds d, r, V'(r) / r, a product and the features' chunk: refused (by
        # TooManyPairsError) where one row passes PAIR_BYTES
        numbers = _FIELD_NUMBERS + 2 * dim + _CHUNK_WIDTHS * self._slope_width()
        check_pair_memory(batch, count, numbers, q.element_size())
        size = int(min(count, max(1, BLOCK_BYTES // (batch * count * numbers * q.element_size()))))
        # components first, (batch, dim, N): a block's sums over the dimension are then sums of whole arrays (a norm
        # over a last axis of 2 was 10x slower than the rest of a block)
        axes = q.transpose(1, 2)
        out = q.new_empty(batch, dim, count)
        for start in range(0, count, size):
            rows = slice(start, min(count, start + size))
            own = torch.arange(rows.start, rows.stop, device=q.device)
            d = axes[:, :, rows, None] - axes[:, :, None, :]                     # (batch, dim, c, N): q_i - q_j
            r = (d * d).sum(dim=1).sqrt_()                                       # (batch, c, N)
            r[:, own - start, own] = 1.0            # a body and itself: any distance in V's domain, its pull zeroed
            pull = self.radial_slope(r) / r
            pull[:, own - start, own] = 0.0
            out[:, :, rows] = (pull[:, None] * d).sum(dim=3)
        return out.transpose(1, 2)

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        self.bodies.count_of(x.shape[1])
        half = x.shape[1] // 2
        return torch.cat([self.kinetic_gradient(x[:, half:]), -self.potential_gradient(x[:, :half])], dim=1)

    # -- the least-squares problems ------------------------------------------------------------------

    def _kinetic_design(self, x, y, weights):
        half = x.shape[1] // 2
        p = self.bodies.bodywise(x[:, half:])
        labels = torch.nn.functional.one_hot(torch.tensor(self.bodies.labels(p.shape[1])),
                                             self.bodies.num_species).to(x.dtype)          # (N, species)
        # column s of component (body b, axis a): p_ba where body b is of species s
        A = p[:, :, :, None] * labels[None, :, None, :]                                    # (rows, N, dim, S)
        A = torch.stack([self.bodies.flat(A[..., s]) for s in range(A.shape[-1])], dim=2)
        return _weighted(A.reshape(-1, A.shape[-1]), y[:, :half].reshape(-1, 1), weights, range(half), half)

    def _potential_design(self, x, y, weights):
        half = x.shape[1] // 2
        q, i, j, d, r, inside = self._geometry(x[:, :half], design=True)
        slopes = _derivative(self.features, r.reshape(-1, 1)).reshape(*r.shape, -1)        # (rows, P, K)
        if inside is not None:      # a pair beyond the cutoff adds no column's slope (the shift is a constant)
            slopes = torch.where(inside[..., None], slopes, 0)
        columns = [-self.bodies.flat(pair_gradient(slopes[..., k], d, r, i, j, q.shape[1]))
                   for k in range(slopes.shape[-1])]
        A = torch.stack(columns, dim=2)                                                    # (rows, N dim, K)
        return _weighted(A.reshape(-1, A.shape[-1]), y[:, half:].reshape(-1, 1), weights,
                         range(half, x.shape[1]), half)

    def _distances(self, x: torch.Tensor) -> torch.Tensor:
        """Every interacting pair's distance in ``x`` ``(pairs, 1)``: what sampled radial neurons are drawn from (with
        a cutoff, those inside it alone: V beyond it is never read)."""
        *_, r, inside = self._geometry(x[:, :x.shape[1] // 2], design=True)
        return (r if inside is None else r[inside]).reshape(-1, 1)

    def _assign(self, target):
        def assign(solution):
            with torch.no_grad():
                target.copy_(solution[:, 0])
        return assign

    def parts(self) -> list[Part]:
        return [Part(None, lambda x: x, self._kinetic_design, self._assign(self.inverse_mass),
                     self.bodies.num_species, name="T"),
                Part(self.features, self._distances, self._potential_design, self._assign(self.coef),
                     self.features.width, name="V")]

    def anchor(self, x0: torch.Tensor, H0) -> None:
        """Fix the constant so that H(x0) = H0 (``x0`` ``(1, 2 N dim)``)."""
        with torch.no_grad():
            self.offset.copy_(torch.as_tensor(H0, dtype=torch.float64).reshape(())
                              - (self.hamiltonian(x0).reshape(()) - self.offset))

    def masses(self) -> torch.Tensor:
        """The fitted mass of each species ``(species,)`` (1 / the inverse mass)."""
        return 1 / self.inverse_mass

    def equation(self, digits: int = 4) -> str:
        """``'H = sum p^2/(2 m) - 1 sum 1/r, m = 1'``: the kinetic energy with its fitted masses, and the pair
        sum of the library's nonzero terms (a sampled fit's neurons have no formula: their count). With a cutoff,
        V's terms and the sum's range: ``'H = sum p^2/(2 m) + sum over r < 2.5 of [V(r) - V(2.5)],
        V = - 4 1/r^6 + 4 1/r^12, m = 1'``."""
        masses = ", ".join(f"{float(m):.{digits}g}" for m in self.masses())
        ending = f", m = {masses}" + (f" by species {list(self.bodies.species)}" if self.bodies.species else "")
        cut = self.bodies.cutoff
        if not self.features.formula:
            sum_v = "sum V(r)" if cut is None else f"sum over r < {cut:g} of [V(r) - V({cut:g})]"
            return f"H = sum p^2/(2 m) + {sum_v}, V a sum of {self.features.width} {self.features.describe('r')}" \
                   f"{ending}"
        pairs = [(float(c), name) for c, name in zip(self.coef.tolist(), self.features.names(["r"])) if c != 0]
        if cut is not None:
            terms = "".join(f" {'-' if c < 0 else '+'} {abs(c):.{digits}g} {name}" for c, name in pairs) or " 0"
            return f"H = sum p^2/(2 m) + sum over r < {cut:g} of [V(r) - V({cut:g})], V ={terms}{ending}"
        text = "".join(f" {'-' if c < 0 else '+'} {abs(c):.{digits}g} sum {name}" for c, name in pairs)
        return f"H = sum p^2/(2 m){text}{ending}"


def _weighted(A, Y, weights, components, per_state):
    """``(A, Y)`` with each row times sqrt(weight of its component) (rows ordered state, component)."""
    if weights is None:
        return A, Y
    w = torch.as_tensor(weights, dtype=A.dtype)[list(components)].sqrt().repeat(len(A) // per_state)[:, None]
    return A * w, Y * w
