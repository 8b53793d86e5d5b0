"""The features a linear fit combines, each with its values and its input gradients in closed form.

- ``TanhFeatures``: one hidden layer of ``width`` neurons, phi_k(x) = tanh(w_k . x + b_k), whose weights
  are drawn from the data (``hnn.fits.sampling``: SWIM's pairs of points, or ELM's random draws) and
  never trained; d phi_k / dx = (1 - phi_k^2) w_k.
- ``Library``: terms written out (``terms``): monomials of the state's columns, sines and cosines of
  the positions, and their products with monomials of the momenta; each prints as its formula, so a
  sparse combination of them prints as an equation.

Both are ``hnn.fits.base.Features`` (the feature sets' interface): ``nn.Module``s whose tensors are
parameters (``requires_grad=False``: drawn or fixed, never trained) and buffers, so a fitted model saves and
reloads as any model does; shapes ``(rows, width)`` for values and ``(rows, width, in_dim)`` for gradients,
float64.
"""
from __future__ import annotations

import itertools
import math

import torch
from torch import nn

from hnn.modes import in_model_axis

from .base import FORMS, Features

# the trig factor of a library term: none, sin(f q_i) or cos(f q_i)
NONE, SIN, COS = 0, 1, 2
ROW_BYTES = 2 ** 27     # a library's gradient is built a few rows at a time, its arrays within this
# a library's solve holds at least one (terms, terms) float64 matrix: a library whose matrix passes this (4 GiB,
# 23170 terms) is refused when it is made, by name, not by the allocator hours or gigabytes later (H's cubic
# library on the 32 columns of 8 bodies in the plane has 63800 terms: 30 GiB, and its gradient factors 187 GB)
LIBRARY_BYTES = 2 ** 32


class LibraryTooLargeError(ValueError):
    """A library whose solve cannot fit ``LIBRARY_BYTES``: the message says its terms, the memory and the fix."""


def _frozen(*shape) -> nn.Parameter:
    return nn.Parameter(torch.zeros(*shape, dtype=torch.float64), requires_grad=False)


class TanhFeatures(Features):
    """phi(x) = tanh(x W^T + b): ``width`` neurons on inputs of width ``in_dim``; ``weight`` ``(width, in_dim)``
    and ``bias`` ``(width,)`` are set by a sampler (``hnn.fits.sampling``), zero until then. Any form: a
    run's ``hidden_dim`` neurons on the inputs its kind reads (x, q, p or a pair distance)."""
    forms = FORMS
    drawn = True

    def __init__(self, width: int, in_dim: int):
        super().__init__()
        if not isinstance(width, int) or width < 1:
            raise ValueError(f"a sampled layer needs a width >= 1 (--hidden_dim), got {width!r}")
        self.width, self.in_dim = width, in_dim
        self.weight, self.bias = _frozen(width, in_dim), _frozen(width)

    @classmethod
    def make(cls, spec, form: str, in_dim: int) -> TanhFeatures:
        """``spec.hidden_dim`` neurons on ``in_dim`` inputs, zero until drawn."""
        return cls(spec.hidden_dim, in_dim)

    def set(self, weight, bias) -> None:
        """Set the sampled ``weight`` ``(width, in_dim)`` and ``bias`` ``(width,)``."""
        with torch.no_grad():
            self.weight.copy_(torch.as_tensor(weight, dtype=torch.float64))
            self.bias.copy_(torch.as_tensor(bias, dtype=torch.float64))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """phi ``(rows, width)`` at ``x`` ``(rows, in_dim)``."""
        return torch.tanh(torch.addmm(self.bias, x, self.weight.T))

    def slopes(self, x: torch.Tensor) -> torch.Tensor:
        """tanh' = 1 - phi^2 ``(rows, width)``: d phi_k / dx = slopes_k w_k."""
        t = self(x)
        return 1 - t * t

    def jacobian(self, x: torch.Tensor) -> torch.Tensor:
        """d phi_k / d x_j ``(rows, width, in_dim)``."""
        return self.slopes(x)[:, :, None] * self.weight[None]

    def gradient_factors(self):
        """``(slopes, weight)``: d phi_k / d x_i = slopes(x)[:, k] * weight[k, i], the Jacobian as a diagonal
        ``(width, in_dim)`` on the slopes (a least-squares solve factors the design through them)."""
        return self.slopes, self.weight

    def gradient(self, x: torch.Tensor, coef: torch.Tensor) -> torch.Tensor:
        """d/dx of phi(x) . coef, ``(rows, in_dim)``: (1 - phi^2) * coef times W, no ``(rows, width, in_dim)`` tensor."""
        t = self(x)
        return ((1 - t * t) * coef) @ self.weight

    def names(self, columns: list[str]) -> list[str]:
        return [f"tanh(w{k} . x + b{k})" for k in range(self.width)]

    def describe(self, column: str) -> str:
        return f"tanh(w {column} + b)"


def _monomials(dim: int, low: int, high: int, columns=None) -> list[tuple[int, ...]]:
    """Exponent tuples of width ``dim`` of total degree ``low..high`` in the ``columns`` (default all), graded."""
    columns = list(range(dim)) if columns is None else list(columns)
    out = []
    for degree in range(low, high + 1):
        for combo in itertools.combinations_with_replacement(columns, degree):
            powers = [0] * dim
            for c in combo:
                powers[c] += 1
            out.append(tuple(powers))
    return out


def terms(width: int, form: str, degree: int, frequencies: int, products: bool = True) -> list[tuple]:
    """The library's terms ``[(powers, (trig, column, frequency))]`` over inputs of ``width`` columns.

    ``form``: ``'hamiltonian'`` (H's terms over x = [q, p]: monomials of degree 1 to ``degree + 1``, so that
    their gradients span the polynomial fields of ``degree``; no constant, which no gradient sees),
    ``'field'`` (dx/dt's terms over [q, p], SINDy's form: a constant and monomials of degree 0 to
    ``degree``), ``'kinetic'`` (T's terms over p alone: monomials of degree 1 to ``degree + 1``) or
    ``'potential'`` (V's terms over q alone: the same, and the trig terms). The trig terms: sin(f q_i)
    and cos(f q_i) for f = 1..``frequencies``; with ``products`` (not in T or V), each of them times the
    monomials of the momenta of degree 1 and 2 (the q-dependent kinetic energies of pendulums).
    """
    halves = form in ("kinetic", "potential")
    if width < 1 or (not halves and width % 2):
        raise ValueError(f"a library of {form} terms reads x = [q, p] of even width, got {width}")
    if degree < 1 or frequencies < 0:
        raise ValueError(f"a library needs degree >= 1 and frequencies >= 0, got {degree}, {frequencies}")
    n, none = (width if halves else width // 2), (NONE, 0, 0)
    if form in ("hamiltonian", "kinetic", "potential"):
        monos = _monomials(width, 1, degree + 1)
    elif form == "field":
        monos = _monomials(width, 0, degree)
    else:
        raise ValueError(f"unknown library form {form!r}: hamiltonian, field, kinetic or potential")
    out = [(m, none) for m in monos]
    if form == "kinetic":
        return out
    trig = [(kind, i, f) for f in range(1, frequencies + 1) for i in range(n) for kind in (SIN, COS)]
    out += [((0,) * width, t) for t in trig]
    if products and not halves:
        out += [(m, t) for t in trig for m in _monomials(width, 1, 2, range(n, width))]
    return out


def term_count(width: int, form: str, degree: int, frequencies: int, products: bool = True) -> int:
    """``len(terms(width, form, degree, frequencies, products))``, counted without listing them."""
    def monomials(dim: int, low: int, high: int) -> int:
        return sum(math.comb(dim + d - 1, d) for d in range(low, high + 1))
    halves = form in ("kinetic", "potential")
    n = width if halves else width // 2
    count = monomials(width, 0, degree) if form == "field" else monomials(width, 1, degree + 1)
    if form == "kinetic":
        return count
    trig = 2 * frequencies * n
    return count + trig + (trig * monomials(width - n, 1, 2) if products and not halves else 0)


class Library(Features):
    """Terms theta_k(x) = x^powers_k * trig_k(x), fixed by ``terms(...)``: ``powers`` ``(terms, in_dim)``
    and ``trig`` ``(terms, 3)`` (kind, column, frequency), buffers. ``make``: the terms of a form (``terms``)
    to the run's ``library_degree`` and ``library_frequencies``, trig terms times momenta where ``products``.

    A monomial is evaluated as the product of its factors' columns (``slots`` ``(terms, degree)``: x^2 y is
    columns (x, x, y), padded with a column of ones), so a value or a gradient costs rows * terms * degree
    multiplications, not rows * terms * in_dim powers (the 3-body's 790 terms on 12 columns: 60x)."""
    forms = ("hamiltonian", "field", "kinetic", "potential")
    formula = True
    subset = True
    products = True     # the trig terms times monomials of the momenta (``terms``' ``products``)

    def __init__(self, term_list: list[tuple], in_dim: int):
        super().__init__()
        self.in_dim, self.width = in_dim, len(term_list)
        # a constant term (the field form's): a field model over it needs no bias of its own
        self.constant = any(not any(powers) and trig[0] == NONE for powers, trig in term_list)
        self.register_buffer("powers", torch.tensor([t[0] for t in term_list], dtype=torch.int64).reshape(-1, in_dim))
        self.register_buffer("trig", torch.tensor([t[1] for t in term_list], dtype=torch.int64).reshape(-1, 3))
        degree = max(1, int(self.powers.sum(dim=1).max())) if self.width else 1
        slots = [[j for j, e in enumerate(row) for _ in range(e)] for row in self.powers.tolist()]
        # derived from ``powers``, so not saved: index in_dim is the column of ones
        self.register_buffer("slots", torch.tensor([s + [in_dim] * (degree - len(s)) for s in slots],
                                                   dtype=torch.int64).reshape(-1, degree), persistent=False)
        # ``transposed``'s rows: x^T, ones, then each distinct trig factor once (kind, column, frequency); each term's
        # trig factor is a row of them (in_dim: the ones)
        distinct = sorted({tuple(t[1]) for t in term_list if t[1][0] != NONE})
        self.register_buffer("angles", torch.tensor(distinct, dtype=torch.int64).reshape(-1, 3), persistent=False)
        self.register_buffer("trig_rows", torch.tensor([in_dim if t[1][0] == NONE else in_dim + 1 + distinct.index(tuple(t[1]))
                                                        for t in term_list], dtype=torch.int64), persistent=False)

    @classmethod
    def make(cls, spec, form: str, in_dim: int) -> Library:
        """The ``form``'s terms on ``in_dim`` columns to ``spec.library_degree`` and ``spec.library_frequencies``;
        a ``LibraryTooLargeError`` where their solve would not fit ``LIBRARY_BYTES``."""
        count = term_count(in_dim, form, spec.library_degree, spec.library_frequencies, products=cls.products)
        if 8 * count ** 2 > LIBRARY_BYTES:
            raise LibraryTooLargeError(
                f"a library of {form} terms of degree {spec.library_degree} and {spec.library_frequencies} "
                f"frequencies on {in_dim} columns has {count} terms: its solve would hold a {count} x {count} "
                f"matrix, {8 * count ** 2 / 2 ** 30:.0f} GiB (limit hnn.fits.features.LIBRARY_BYTES = "
                f"{LIBRARY_BYTES / 2 ** 30:.0f} GiB); ask for a lower --library_degree or --library_frequencies 0, "
                "or, on a scene of bodies, --model pairwise --fit library (a library of one distance)")
        return cls(terms(in_dim, form, spec.library_degree, spec.library_frequencies, products=cls.products), in_dim)

    def _parts(self, x: torch.Tensor, keep: torch.Tensor | None, slopes: bool = True):
        """Per term: the monomial's factors (a list of ``degree`` tensors ``(rows, terms)``), the trig factor and
        its derivative ``(rows, terms)`` (None without ``slopes``: a value needs none), and the terms' ``slots``
        and ``trig`` rows (``keep``: a subset)."""
        slots, trig = (self.slots, self.trig) if keep is None else (self.slots[keep], self.trig[keep])
        if slopes:
            padded = torch.cat([x, x.new_ones(len(x), 1)], dim=1)
            factors = [padded[:, slots[:, s]] for s in range(slots.shape[1])]
        else:   # a factor as a gather of whole rows of x^T (3-5x faster than of columns), viewed as (rows, terms)
            padded = torch.cat([x.T, x.new_ones(1, len(x))])
            factors = [padded[slots[:, s]].T for s in range(slots.shape[1])]
        angle = x[:, trig[:, 1]] * trig[:, 2].to(x.dtype)
        kind, freq = trig[:, 0], trig[:, 2].to(x.dtype)
        sin, cos = torch.sin(angle), torch.cos(angle)
        t = torch.where(kind == SIN, sin, torch.where(kind == COS, cos, torch.ones_like(angle)))
        if not slopes:
            return factors, t, None, slots, trig
        dt = torch.where(kind == SIN, freq * cos, torch.where(kind == COS, -freq * sin, torch.zeros_like(angle)))
        return factors, t, dt, slots, trig

    @staticmethod
    def _product(factors: list) -> torch.Tensor:
        out = factors[0]
        for f in factors[1:]:
            out = out * f
        return out

    def forward(self, x: torch.Tensor, keep: torch.Tensor | None = None) -> torch.Tensor:
        """theta ``(rows, terms)`` at ``x`` ``(rows, in_dim)`` (``keep``: only those terms)."""
        factors, t, *_ = self._parts(x, keep, slopes=False)
        # the same products as ever, elementwise (the bits do not depend on the layout); row-major out, as before,
        # for the products a caller takes of it
        return (self._product(factors) * t).contiguous()

    def transposed(self, x: torch.Tensor) -> torch.Tensor:
        """theta^T ``(terms, rows)`` at ``x`` ``(rows, in_dim)``, contiguous: ``forward``'s values and products in its
        order (the monomial's factors, then the trig factor), built in place on the transposed layout, where a
        factor is a gather of whole rows of x^T and the trig factors' sines and cosines are taken once per
        distinct angle (the 3-body's field library: 12 rows, not 336 terms' worth). Its ``.T`` is the
        column-major ``(rows, terms)`` a least-squares solve's QR reads (``hnn.fits.models.FittedField``)."""
        n, angles = self.in_dim, self.angles
        rows = x.new_empty(n + 1 + len(angles), len(x))
        rows[:n] = x.T
        rows[n] = 1.0
        for kind in (SIN, COS):
            pick = (angles[:, 0] == kind).nonzero()[:, 0]
            if len(pick):
                angle = x.T[angles[pick, 1]] * angles[pick, 2, None].to(x.dtype)
                rows[n + 1 + pick] = torch.sin(angle) if kind == SIN else torch.cos(angle)
        out = rows[self.slots[:, 0]]
        for s in range(1, self.slots.shape[1]):
            out.mul_(rows[self.slots[:, s]])
        return out.mul_(rows[self.trig_rows])

    def _rows_at_once(self, terms: int) -> int:
        """Rows of ``x`` whose ``(rows, terms)`` intermediates of a gradient (about degree + 4 of them) stay
        within ``ROW_BYTES`` (the 3-body's 790 terms on its test states once built arrays of gigabytes)."""
        return max(1, ROW_BYTES // (8 * max(terms, 1) * (self.slots.shape[1] + 4)))

    def _slopes(self, x, keep):
        """d theta / d(factor s) for each slot s (a list of ``(rows, terms)``; the product of the other factors,
        no division), the trig factor's share ``(rows, terms)``, and the ``slots`` and ``trig`` rows."""
        factors, t, dt, slots, trig = self._parts(x, keep)
        d = len(factors)
        before, after = [None] * d, [None] * d
        for s in range(1, d):
            before[s] = factors[s - 1] if before[s - 1] is None else before[s - 1] * factors[s - 1]
            after[d - 1 - s] = factors[d - s] if after[d - s] is None else after[d - s] * factors[d - s]
        others = [t if b is None and a is None else (b if a is None else a if b is None else b * a) * t
                  for b, a in zip(before, after)]
        return others, self._product(factors) * dt, slots, trig

    def _columns(self, index: torch.Tensor, dtype) -> torch.Tensor:
        """One-hot ``(terms, in_dim + 1)`` of the column each term's factor sits in (in_dim: the ones)."""
        return torch.nn.functional.one_hot(index, self.in_dim + 1).to(dtype)

    def jacobian(self, x: torch.Tensor, keep: torch.Tensor | None = None) -> torch.Tensor:
        """d theta_k / d x_j ``(rows, terms, in_dim)``: the product rule over the monomial's factors and the trig
        factor (x^2 has slots (x, x): each adds x, 2x in all; the ones column is dropped)."""
        others, trig_slope, slots, trig = self._slopes(x, keep)
        rows, terms = trig_slope.shape
        jac = x.new_zeros(rows, terms, self.in_dim + 1)
        for s, slope in enumerate(others):
            jac.scatter_add_(2, slots[:, s][None, :, None].expand(rows, -1, 1), slope[:, :, None])
        jac.scatter_add_(2, trig[:, 1][None, :, None].expand(rows, -1, 1), trig_slope[:, :, None])
        return jac[:, :, :self.in_dim]

    def gradient(self, x: torch.Tensor, coef: torch.Tensor) -> torch.Tensor:
        """d/dx of theta(x) . coef ``(rows, in_dim)``, over the terms whose coefficient is not zero: per slot,
        ``(rows, terms) @ (terms, in_dim)``, no ``(rows, terms, in_dim)`` tensor."""
        if in_model_axis():     # under vmap over a group's models no value decides a shape: every term, zeros too
            keep, kept, count = None, coef[:, None], self.width
        else:
            keep = coef != 0
            if not bool(keep.any()):
                return torch.zeros_like(x)
            kept, count = coef[keep][:, None], int(keep.sum())
        slots, trig, rows = self.slots if keep is None else self.slots[keep], self.trig if keep is None else self.trig[keep], \
            self._rows_at_once(count)
        columns = [self._columns(slots[:, s], x.dtype) * kept for s in range(slots.shape[1])]
        trig_columns = self._columns(trig[:, 1], x.dtype) * kept

        def chunk(xc):
            others, trig_slope, *_ = self._slopes(xc, keep)
            grad = trig_slope @ trig_columns
            for slope, onto in zip(others, columns):
                grad = grad + slope @ onto
            return grad[:, :self.in_dim]
        return chunk(x) if len(x) <= rows else torch.cat([chunk(x[i:i + rows]) for i in range(0, len(x), rows)])

    def gradient_factors(self):
        """``(basis, C)``: every partial derivative of every term as a combination of a few functions,
        d theta_k / d x_i = sum_m basis(x)[:, m] C[m, k, i]; ``basis`` a callable, ``(rows, M)`` at ``x``
        ``(rows, in_dim)``, evaluating the distinct terms the derivatives are made of (a ``Library`` of
        them: x^2 y gives 2 x y and x^2, sin(f q) p gives f cos(f q) p and sin(f q)); ``C`` ``(M, terms,
        in_dim)``. A least-squares fit of the gradients factors its design through them: the 3-body's 790
        cubic terms on 12 columns have 427 such functions, so one QR of the states' ``(rows, 427)`` values
        replaces one of the ``(12 rows, 790)`` Jacobian rows, a thirtieth of the arithmetic."""
        index: dict[tuple, int] = {}
        entries = []        # (m, k, i, value)
        for k, (powers, trig) in enumerate(zip(self.powers.tolist(), self.trig.tolist())):
            kind, column, freq = trig
            for i in range(self.in_dim):
                parts = []
                if powers[i]:
                    parts.append((powers[i], tuple(powers[:i]) + (powers[i] - 1,) + tuple(powers[i + 1:]),
                                  tuple(trig)))
                if kind != NONE and column == i:     # sin(f q)' = f cos(f q), cos(f q)' = -f sin(f q)
                    parts.append((freq if kind == SIN else -freq, tuple(powers),
                                  (COS if kind == SIN else SIN, column, freq)))
                for value, term_powers, term_trig in parts:
                    m = index.setdefault((term_powers, term_trig), len(index))
                    entries.append((m, k, i, float(value)))
        # the basis ordered plain monomials, then sin, then cos terms (the order of the factor's columns: round-off)
        keys = sorted(index, key=lambda key: key[1][0])
        position = torch.tensor([keys.index(key) for key in index])
        C = torch.zeros(len(index), self.width, self.in_dim, dtype=torch.float64)
        if entries:
            m, k, i, value = zip(*entries)
            C.index_put_((position[list(m)], torch.tensor(k), torch.tensor(i)),
                         torch.tensor(value, dtype=torch.float64), accumulate=True)
        basis = Library([(list(p), list(t)) for p, t in keys], self.in_dim).to(self.powers.device)

        def values(x: torch.Tensor) -> torch.Tensor:
            # built in place on the transposed (M, rows) (``transposed``): a gather of columns of (rows, in_dim) and
            # forward's trig factor and slope of every term cost 3-10x as much
            return basis.transposed(x).T
        return values, C

    def names(self, columns: list[str]) -> list[str]:
        """Each term as a formula over the column names (``'q^2 p'``, ``'cos(q)'``, ``'sin(2 q1) p1 p2'``)."""
        out = []
        for powers, (kind, column, freq) in zip(self.powers.tolist(), self.trig.tolist()):
            parts = []
            if kind != NONE:
                parts.append(f"{'sin' if kind == SIN else 'cos'}({'' if freq == 1 else f'{freq} '}{columns[column]})")
            parts += [name + (f"^{e}" if e > 1 else "") for name, e in zip(columns, powers) if e]
            out.append(" ".join(parts) or "1")
        return out
