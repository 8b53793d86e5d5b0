"""A pair model's V(r) as a table: the model's H to a declared tolerance, at about the cost of a scene's true forces.

A pair model (``PairHNN`` trained by Adam, or the least-squares ``hnn.fits.radial.FittedPair``) spends its field
call on V'(r) at every pair: at width 64, two 64 x 64 products a pair, where a scene's true force is a few
operations. V is a function of one distance, so a table answers the same question with a gather and a cubic, as
molecular dynamics codes run a potential given by numbers. ``TabulatedPair`` samples the model's V' at knots
uniform in s = log r over ``r_range``, joins dV/ds by cubic Hermite pieces (their ends' derivatives by second-order
differences) and takes V as their integral, anchored at the model's V at r_hi: the table's V' is the exact
derivative of its V, so a split integrator conserves the table's H as it does the model's. Built from V' alone, the
slope never reads the rounding of V divided by the knots' spacing (a sampled fit's V is a sum of large cancelling
terms). Log spacing resolves a steep wall near the closest distances and a slow tail far out with the same knots.

The knots double from ``START_KNOTS`` until V' at the pieces' quarter points, midpoints and three-quarter points
is within ``tol`` of the model's, relative to |V'| there plus its median size over the check points (V' crosses
zero at a potential's minimum, and a wall's steep slopes would make a mean lax everywhere else); ``max_error`` is
what was reached. Past ``MAX_KNOTS``, or where doubling the knots makes the error grow (the rounding of the
model's own V'), it is refused, naming the error reached. A pair outside ``r_range`` (or a NaN distance)
reads the model itself, so the table never extrapolates.

For evaluation (rollouts, energies): the table holds numbers, not the model's parameters; train the model, then
tabulate it. Shapes as ``hnn.models.pair``'s: states ``(batch, 2 N dim)``, per-pair arrays ``(batch, P)``.
"""
from __future__ import annotations

import math

import torch

from ..interface import Model
from .pair import check_pair_memory, find_pairs, inside_cutoff, pair_gradient, separations

START_KNOTS = 1025
MAX_KNOTS = 2 ** 18 + 1      # (K - 1) x 7 float64 coefficients: 14 MB
_BUILD_ROWS = 4096           # distances the model reads at once while the table is built


class TabulatedPair(Model):
    """``model``'s pair potential tabulated over ``r_range`` = (r_lo, r_hi) to relative slope error ``tol``.

    ``model``: a pair model with ``bodies``, ``radial(r)`` and ``radial_slope(r)`` ``(batch, P) -> (batch, P)``,
    ``kinetic`` and ``kinetic_gradient``; its kinetic energy (the masses) is its own, read through. With a cutoff
    the table ends at r_c (beyond it no pair interacts). ``knots``, ``max_error``: the table's size and the slope
    error it reached at the check points."""
    conservative = True
    separable = True

    def __init__(self, model: Model, r_range: tuple[float, float], tol: float = 1e-8):
        super().__init__()
        if not callable(getattr(model, "radial_slope", None)) or not hasattr(model, "bodies"):
            raise TypeError(f"TabulatedPair tabulates a pair model's V(r) (PairHNN or the least-squares FittedPair), "
                            f"got {type(model).__name__}")
        if getattr(model, "external_net", None) is not None:
            raise ValueError("this pair model has a one-body field U(q_i) besides V(r): a table holds V alone; roll "
                             "the model out itself")
        lo, hi = (float(v) for v in r_range)
        if not 0 < lo < hi or not math.isfinite(hi):
            raise ValueError(f"r_range={r_range}: give two finite distances 0 < r_lo < r_hi, the distances the "
                             "paths' pairs will take (pairs outside read the model itself)")
        if not 0 < tol < 1:
            raise ValueError(f"tol={tol}: give a relative slope error between 0 and 1, e.g. 1e-8")
        self.model, self.bodies, self.input_dim, self.tol = model, model.bodies, model.input_dim, tol
        if self.bodies.pairs == "cutoff":
            if lo >= self.bodies.cutoff:
                raise ValueError(f"r_range={r_range} starts past the cutoff {self.bodies.cutoff:g}, where no pair "
                                 "interacts: start it below")
            hi = min(hi, self.bodies.cutoff)
        self.r_range = (lo, hi)
        dtype = next(model.parameters()).dtype
        with torch.no_grad():
            self._build(dtype)

    def _model_slope(self, r: torch.Tensor) -> torch.Tensor:
        """The model's V' at distances ``r`` ``(K,)``, a block of rows at a time."""
        return torch.cat([self.model.radial_slope(r[None, k:k + _BUILD_ROWS])[0]
                          for k in range(0, len(r), _BUILD_ROWS)])

    def _build(self, dtype: torch.dtype) -> None:
        """Knots doubled until the slope error at the check points is within ``tol``; the pieces' coefficients."""
        lo, hi = (math.log(v) for v in self.r_range)
        top = float(self.model.radial(torch.tensor([[self.r_range[1]]], dtype=dtype))[0, 0])
        knots, previous = START_KNOTS, math.inf
        while True:
            s = torch.linspace(lo, hi, knots, dtype=dtype)
            self._set_pieces(s, self._model_slope(s.exp()) * s.exp(), top)
            h = float(s[1] - s[0])
            checks = (s[:-1, None] + h * torch.tensor([0.25, 0.5, 0.75], dtype=dtype)).reshape(-1).exp()
            truth = self._model_slope(checks)
            scale = truth.abs() + truth.abs().median()
            self.max_error = float(((self.radial_slope(checks[None])[0] - truth).abs() / scale).max())
            if self.max_error <= self.tol:
                break
            # halving h cuts the pieces' error 8x once they resolve V'; where it grows instead, the rounding of the
            # model's own V' dominates and more knots cannot help
            stalled = self.max_error >= previous
            if stalled or knots >= MAX_KNOTS:
                why = "where more knots no longer reduce it (the rounding of the model's V')" if stalled \
                    else f"(at most {MAX_KNOTS})"
                raise ValueError(f"V' of this model over r_range={self.r_range} reached a relative error of "
                                 f"{self.max_error:.2g} at {knots} knots {why}, above tol={self.tol:g}: narrow "
                                 "r_range to the distances the paths take, or raise tol")
            previous, knots = self.max_error, 2 * knots - 1
        self.knots = knots

    def _set_pieces(self, s: torch.Tensor, f: torch.Tensor, top: float) -> None:
        """Each piece's f = dV/ds = a + b t + c t^2 + d t^3, t = (log r - s_k) / h: cubic Hermite from f at its
        ends and df/ds by differences of f (second order: central inside, three points at the ends); and V its
        integral, V_k + h (a t + b t^2 / 2 + c t^3 / 3 + d t^4 / 4), V at the top knot ``top`` (the model's). From
        V' alone, so the rounding of the model's V (a sampled fit's large cancelling coefficients) never enters
        the slope divided by h."""
        h = s[1] - s[0]
        m = torch.empty_like(f)                                    # df/ds at the knots, times h
        m[1:-1] = (f[2:] - f[:-2]) / 2
        m[0] = (-3 * f[0] + 4 * f[1] - f[2]) / 2
        m[-1] = (3 * f[-1] - 4 * f[-2] + f[-3]) / 2
        a, f1, m0, m1 = f[:-1], f[1:], m[:-1], m[1:]
        c = 3 * (f1 - a) - 2 * m0 - m1
        d = 2 * (a - f1) + m0 + m1
        rise = h * (a + m0 / 2 + c / 3 + d / 4)                    # V over each piece
        start = top - rise.flip(0).cumsum(0).flip(0)               # V at each piece's start
        self.s_lo, self.h, self.pieces = float(s[0]), float(h), len(s) - 1
        # buffers: they follow the model's .to(device) (not saved: a table is rebuilt from its model)
        self.register_buffer("value_coef", torch.stack([start, h * a, h * m0 / 2, h * c / 3, h * d / 4], dim=1),
                             persistent=False)
        self.register_buffer("slope_coef", torch.stack([a, m0, c, d], dim=1), persistent=False)

    def _locate(self, r: torch.Tensor):
        """``(inside, k, t)``: which distances the table covers, each one's piece and its place t in [0, 1]
        (a distance outside reads piece 0, its value then replaced by the model's)."""
        lo, hi = self.r_range
        covered = (r >= lo) & (r <= hi)                            # False for NaN
        z = (torch.where(covered, r, lo).log() - self.s_lo) / self.h
        k = z.floor().clamp_(0, self.pieces - 1)
        return covered, k.long(), z - k

    def _outside(self, r, covered, out, read) -> torch.Tensor:
        """``out`` with the distances the table does not cover replaced by the model's ``read``."""
        if covered.all():
            return out
        missed = ~covered
        out = out.clone()
        out[missed] = read(r[missed][None])[0]
        return out

    def radial(self, r: torch.Tensor) -> torch.Tensor:
        """V(r) ``(batch, P)`` of distances ``r`` ``(batch, P)``: the table's, the model's outside ``r_range``."""
        covered, k, t = self._locate(r)
        v, a, b, c, d = self.value_coef[k].unbind(-1)
        return self._outside(r, covered, v + t * (a + t * (b + t * (c + t * d))), self.model.radial)

    def radial_slope(self, r: torch.Tensor) -> torch.Tensor:
        """V'(r) ``(batch, P)`` of distances ``r`` ``(batch, P)``: the table's, the model's outside ``r_range``."""
        covered, k, t = self._locate(r)
        a, b, c, d = self.slope_coef[k].unbind(-1)
        return self._outside(r, covered, (a + t * (b + t * (c + t * d))) / r, self.model.radial_slope)

    def _pairs(self, q_half: torch.Tensor):
        q = self.bodies.bodywise(q_half)
        i, j = find_pairs(q, self.bodies)
        check_pair_memory(len(q), len(i), 4 + 3 * self.bodies.dim, q.element_size())
        d, r = separations(q, i, j)
        return q, i, j, d, r, inside_cutoff(r, self.bodies)

    def kinetic(self, p_half: torch.Tensor) -> torch.Tensor:
        """T ``(batch,)``: the model's."""
        return self.model.kinetic(p_half)

    def kinetic_gradient(self, p_half: torch.Tensor) -> torch.Tensor:
        """dT/dp ``(batch, N dim)``: the model's."""
        return self.model.kinetic_gradient(p_half)

    def potential(self, q_half: torch.Tensor) -> torch.Tensor:
        """V ``(batch,)``: the pairs' tabulated V(r); with a cutoff, V(r) - V(r_c) over the pairs inside it."""
        *_, r, inside = self._pairs(q_half)
        if inside is None:
            return self.radial(r).sum(dim=1)
        shift = self.radial(r.new_full((1, 1), self.bodies.cutoff))
        return torch.where(inside, self.radial(r) - shift, 0).sum(dim=1)

    def potential_gradient(self, q_half: torch.Tensor) -> torch.Tensor:
        """dV/dq ``(batch, N dim)``: each pair's tabulated V'(r) along its separation, O(pairs)."""
        q, i, j, d, r, inside = self._pairs(q_half)
        slope = self.radial_slope(r)
        if inside is not None:
            slope = torch.where(inside, slope, 0)
        return self.bodies.flat(pair_gradient(slope, d, r, i, j, q.shape[1]))

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H ``(batch,)`` at ``x`` ``(batch, 2 N dim)``: the model's kinetic energy and the table's V."""
        self.bodies.count_of(x.shape[1])
        half = x.shape[1] // 2
        return self.kinetic(x[:, half:]) + self.potential(x[:, :half]) + getattr(self.model, "offset", 0)

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        """dx/dt = [dT/dp, -dV/dq] ``(batch, 2 N dim)``."""
        self.bodies.count_of(x.shape[1])
        half = x.shape[1] // 2
        return torch.cat([self.kinetic_gradient(x[:, half:]), -self.potential_gradient(x[:, :half])], dim=1)
