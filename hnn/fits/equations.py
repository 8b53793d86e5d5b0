"""A library fit's equation as text, in the coordinates it was fit in or in the user's columns and units.

    hnn.fits.equation(model)                        # 'H = q^2 + p^2': a library model, or a Rescaled one
    hnn.fits.equation(inner, Frame(("x", "v"), scale=(a, b), shift=(x0, 0.0), time=a / b))

A fit made in scaled coordinates x' = (x - shift) / scale, t' = t / time (``hnn.units.Rescaled``'s canonical
units: no shift; the measured study's q' = (q - q0) / a, v' = v / b, t' = t b / a) answers in the user's:
H(x) = energy * H'(x') with energy = s_q s_p / time, the one factor that keeps Hamilton's equations
(``hnn.units.UnitScales.energy``), and dx_j/dt = scale_j / time * f'_j(x'). A polynomial term expands exactly:
((x - m) / s)^e is a polynomial of x (binomially), so the printed coefficients are the user's. A sine or
cosine of a scaled column stays one, with its argument written out: cos(f (q - m) / s) prints as
``cos(a q - b)`` (a = f / s, b = f m / s), which says that the library's term read the scaled column.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import torch

from .features import COS, NONE, SIN, Library


def column_names(input_dim: int) -> list[str]:
    """``['q', 'p']`` for one degree of freedom, ``['q1', .., 'qn', 'p1', .., 'pn']`` for more."""
    n = input_dim // 2
    if n == 1:
        return ["q", "p"]
    return [f"q{i + 1}" for i in range(n)] + [f"p{i + 1}" for i in range(n)]


@dataclass(frozen=True)
class Frame:
    """Where a fit's coordinates sit in the user's: column j is x_j = scale_j * x'_j + shift_j, time
    t = time * t'; ``names``: the user's column names (positions, then momenta or velocities)."""
    names: tuple[str, ...]
    scale: tuple[float, ...]
    shift: tuple[float, ...]
    time: float = 1.0

    def __post_init__(self):
        for name in ("names", "scale", "shift"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if not len(self.names) == len(self.scale) == len(self.shift):
            raise ValueError(f"a Frame needs one name, scale and shift per column, got {len(self.names)}, "
                             f"{len(self.scale)}, {len(self.shift)}")
        if not (all(s > 0 and math.isfinite(s) for s in self.scale) and self.time > 0
                and all(math.isfinite(m) for m in self.shift)):
            raise ValueError(f"a Frame's scales and time must be positive and finite, its shifts finite: got "
                             f"scale={self.scale}, shift={self.shift}, time={self.time}")

    @classmethod
    def own(cls, input_dim: int) -> Frame:
        """The fit's own coordinates: q and p (``column_names``), unscaled."""
        return cls(tuple(column_names(input_dim)), (1.0,) * input_dim, (0.0,) * input_dim)

    def outside(self, scales, coordinates: str = "canonical") -> Frame:
        """This frame seen from a model fit inside ``hnn.units.Rescaled`` ``scales`` (its x = c * x'', t = s_t t''):
        the composition x = scale * c * x'' + shift, t = time * s_t * t''."""
        c = scales.state(coordinates, len(self.names)).tolist()
        return Frame(self.names, tuple(s * k for s, k in zip(self.scale, c)), self.shift, self.time * scales.t)

    def columns(self, which: slice) -> Frame:
        """The frame of some columns (a separable H's q or p), its time kept."""
        return Frame(self.names[which], self.scale[which], self.shift[which], self.time)

    @property
    def energy(self) -> float:
        """s_q s_p / time: H = energy * H'. Every pair must have one product (else no H keeps its form)."""
        n = len(self.names) // 2
        products = np.asarray(self.scale[:n]) * np.asarray(self.scale[n:2 * n])
        if n == 0 or np.abs(products / products[0] - 1).max() > 1e-9:
            raise ValueError(f"an H reads pairs (q_i, p_i) of one product of scales; this frame's are "
                             f"{products.tolist()}")
        return float(products[0] / self.time)


def _expand(library: Library, coef: torch.Tensor, frame: Frame) -> dict:
    """``{(powers, trig): [coefficient, sum of |contributions|, contributions]}`` of sum_k coef_k theta_k(x') over
    the user's columns x: each monomial prod_j ((x_j - m_j) / s_j)^e_j expanded binomially; ``trig`` None or
    ``(kind, column, frequency, a, b)``, the factor trig(a x_column + b)."""
    out = {}
    m, s = frame.shift, frame.scale
    for c, powers, (kind, column, freq) in zip(coef.tolist(), library.powers.tolist(), library.trig.tolist()):
        if c == 0:
            continue
        trig = None if kind == NONE else (kind, column, freq, freq / s[column], -freq * m[column] / s[column])
        factors = [[(i, math.comb(e, i) * (-m[j]) ** (e - i) / s[j] ** e) for i in range(e + 1)]
                   for j, e in enumerate(powers)]
        for choice in itertools.product(*factors):
            value = c * math.prod(v for _, v in choice)
            if value == 0:          # an unshifted column: only its top power
                continue
            sums = out.setdefault((tuple(i for i, _ in choice), trig), [0.0, 0.0, 0])
            sums[0] += value
            sums[1] += abs(value)
            sums[2] += 1
    return out


def _order(key) -> tuple:
    """The library's order (``hnn.fits.features.terms``): monomials by degree then columns, then the trig terms by
    frequency, column and kind, then their products with monomials."""
    powers, trig = key
    combo = tuple(j for j, e in enumerate(powers) for _ in range(e))
    if trig is None:
        return 0, len(combo), combo
    return 1, len(combo) > 0, trig[2], trig[1], trig[0], len(combo), combo


def _name(key, names: tuple[str, ...], digits: int) -> str:
    powers, trig = key
    parts = []
    if trig is not None:
        kind, column, _, a, b = trig
        slope = "" if a == 1 else f"{a:.{digits}g} "
        shift = "" if b == 0 else f" {'-' if b < 0 else '+'} {abs(b):.{digits}g}"
        parts.append(f"{'sin' if kind == SIN else 'cos' if kind == COS else '?'}({slope}{names[column]}{shift})")
    parts += [name + (f"^{e}" if e > 1 else "") for name, e in zip(names, powers) if e]
    return " ".join(parts) or "1"


def terms(library: Library, coef: torch.Tensor, frame: Frame, factor: float = 1.0, digits: int = 4,
          constant: float = 0.0) -> tuple[float, list[tuple[float, str]]]:
    """``(constant, [(coefficient, term)])``: ``factor * (sum_k coef_k theta_k(x') + constant)`` over the
    user's columns, in the library's order, the constant apart. A coefficient that cancels to round-off
    (under (contributions + degree + 2) float64 epsilons of the sizes summed into it) is dropped."""
    expanded = _expand(library, coef, frame)
    zero = (tuple(0 for _ in frame.names), None)
    entry = expanded.setdefault(zero, [0.0, 0.0, 0])
    entry[0] += constant
    entry[1] += abs(constant)
    entry[2] += 1
    eps = np.finfo(np.float64).eps
    pairs = []
    for key in sorted(expanded, key=_order):
        value, size, count = expanded[key]
        if abs(value) <= (count + sum(key[0]) + 2) * eps * size:
            continue
        pairs.append((factor * value, _name(key, frame.names, digits)))
    constant = sum(c for c, name in pairs if name == "1")
    return constant, [(c, name) for c, name in pairs if name != "1"]


def written(constant: float, pairs: list[tuple[float, str]], digits: int) -> str:
    """``'3 - 3 cos(q) + p^2'``: the constant first (where not 0), then the terms as given; ``'0'`` if none."""
    text = ""
    for i, (c, name) in enumerate(([(constant, "1")] if constant else []) + pairs):
        sign = ("-" if c < 0 else "") if i == 0 else (" - " if c < 0 else " + ")
        value = f"{abs(c):.{digits}g}"
        text += sign + (name if value == "1" and name != "1" else value if name == "1" else f"{value} {name}")
    return text or "0"


def equation(model, frame: Frame | None = None, digits: int = 4) -> str:
    """The equation of a library fit ``model`` (``FittedHNN``, ``FittedSeparable``, ``FittedField`` over a
    ``Library``, or an ``hnn.units.Rescaled`` of one) in ``frame`` (default: the model's own q and p; a
    Rescaled model answers in the user's units of its scales): ``'H = ...'``, or ``'dq/dt = ...; dp/dt = ...'``."""
    from ..units import Rescaled

    if isinstance(model, Rescaled):
        frame = (frame or Frame.own(model.input_dim)).outside(model.scales, model.inner.coordinates)
        model = model.inner
    if not hasattr(model, "equation"):
        raise ValueError(f"a {type(model).__name__} is no library fit: it has no equation (fit='library' or 'sindy')")
    return model.equation(digits=digits, frame=frame)
