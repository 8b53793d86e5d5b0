"""Unit invariance: a run trains in canonical units of its own data, and its saved model answers in the user's.

    model = hnn.units.Rescaled(inner)          # hnn.train fits s_q, s_p, s_t from the training data
    hnn.train(model, x, dxdt)                  # inner trains on q' = q / s_q, p' = p / s_p, t' = t / s_t
    model.time_derivative(x)                   # dx/dt in the user's units

    scales = hnn.units.fit_scales(x, dxdt, "canonical")        # the same by hand
    hnn.train(inner, *scales.to_canonical(x, dxdt, "canonical"), units="off")
    model = hnn.units.Rescaled(inner, scales)

The rescaling keeps Hamilton's equations: with q' = q / s_q, p' = p / s_p and t' = t / s_t the
flow of H is the flow of H' = H s_t / (s_q s_p) in the primed coordinates, so a model of H'
is a model of H = ``energy`` H'(x / c), c = [s_q .. s_p ..], ``energy`` = s_q s_p / s_t. One s_q for
every position and one s_p for every momentum where that serves; per coordinate (s_q_i, s_p_i) where
the columns' sizes spread too far for one (bodies of very different mass), with one product s_q_i s_p_i
for every pair, which keeps one H (``fit_scales``). A change of units of all q, all p or t is undone
exactly, since the scales are RMS values of the data, which scale with them. Angles (``periodic``) keep
s_q = 1: a network that reads cos q, sin q fixes the radian.

Fit on states ``[q, qdot]`` (``'velocity'``, ``'cartesian'``) the momentum scale is s_q / s_t (unit
mass: a mass is not observable from velocities) and s_t makes the velocities' RMS 1.

``--units`` (``hnn.RunConfig.units``; ``hnn.train``'s ``units``): ``auto`` (the default: rescales where
the RMS of q or p lies outside [0.1, 10] or that of dq/dt or dp/dt outside [0.01, 100], ``AUTO_FAR``,
which no published run's data do, so each trains in its data's units, bit for bit as before), ``on``
(always) or ``off`` (never). A rescaled run records ``unit_scales`` in its args.json; ``hnn.kinds.model_from_args``
wraps the rebuilt model in ``Rescaled`` from them, so ``hnn.load_run`` answers in the user's units. Such
a run's loss history (metrics.json's ``history``), its ``loss_weights`` and any ``input_noise`` are in
the canonical units; its final train and test losses are the saved model's, in the user's. It trains
alone, never in a group (``hnn.sweeps.group_runs.train_group``).

Supported: fits of dx/dt (``--objective derivative``, with or without ``--use_rk4``, whose dt is
rescaled too) of every kind that reads [q, p] or [q, qdot]: hnn, baseline, separable, dissipative,
mechanical (on [q, p], or mapping observed [q, qdot]), second_order and lagrangian. Refused, with a
ValueError naming ``--units off``, where the rescaling would apply (``on``, or ``auto`` on data far from
unit scale): the constrained kinds (their constraint graph holds rod lengths in the user's units, which
the model does not rescale) and the path objectives (trajectory, discrete_gradient: their snippets step
the data's own time; not built yet). A learned map's objective reads no rate and no time (it fits a state to
the next one), so ``auto`` judges its states alone: a file whose time is in milliseconds trains the same map
as in seconds. The pixel kinds read pixels (no q and p): ``on`` refuses them,
``auto`` leaves them as they are.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
import torch

from .interface import Model, observed_coordinates
from .names import UNITS

# 'auto' (the default) rescales where the RMS of q or p (what a network reads) lies outside
# [1 / AUTO_FAR["q"], AUTO_FAR["q"]], or that of dq/dt or dp/dt (what it is fit to) outside
# [1 / AUTO_FAR["dq/dt"], AUTO_FAR["dq/dt"]]. The published runs' data lie inside (``python
# analysis/units_check.py`` prints each: the tasks' defaults, the chains of the peers' tables, the
# studies' scenes), so 'auto' trains each as 'off' does and no published number moves: their states lie
# within 0.11-5.8, their rates within 0.11-35 (the 5-bob chain's accelerations, which [0.1, 10] for the rates
# too would have rescaled). The bounds are set by those data, not by a size where fits stop degrading: a
# spring fit in its own units degrades gradually, several times already at states 3x or rates 10x unit size
# (docs/stress.md, "Where auto starts"), 20-50x past the bounds; at 10^-3 and 10^3 the stress study's cells
# without the rescaling degrade, with it they work. 'on' rescales everything: not the default, since its
# scales are never exactly 1 and it would move every published number.
AUTO_FAR = {"q": 10.0, "p": 10.0, "dq/dt": 100.0, "dp/dt": 100.0}
# the spread of one block's columns (all q, ...) past which one scale cannot serve them all (fit_scales)
COLUMN_SPREAD = 10.0
# the state coordinates whose second half is a velocity (its scale s_q / s_t), and those it is a momentum
VELOCITY_LIKE = ("velocity", "cartesian")
CANONICAL_LIKE = ("canonical",)
# the pixel kinds read pixels and learn their own latent: no q and p to scale
_PIXELS = "it reads pixels, not q and p (its latent coordinates are learned, of no unit)"
# one product s_q_i s_p_i for every pair: checked to this relative tolerance
_PRODUCT_RTOL = 1e-9


def _numpy(a) -> np.ndarray:
    """``a`` (an array or a tensor) as a float64 array."""
    return np.asarray(a.detach().cpu() if torch.is_tensor(a) else a, dtype=np.float64)


def _rms(a: np.ndarray, name: str) -> float:
    value = float(np.sqrt(np.mean(np.square(a, dtype=np.float64))))
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"--units: the RMS of {name} in the training data is {value}, so it has no scale to "
                         "divide by; use --units off")
    return value


def _column_rms(a: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.square(a, dtype=np.float64), axis=0))


def _per_pair(value, n: int, name: str) -> np.ndarray:
    """A scale given as one number or one per coordinate, as ``(n,)`` float64."""
    v = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if v.shape == (1,):
        return np.full(n, v[0])
    if v.shape != (n,):
        raise ValueError(f"UnitScales.{name} has {v.size} scales for a state of {n} coordinate pairs")
    return v


@dataclass(frozen=True)
class UnitScales:
    """The canonical rescaling of a run: ``q``, ``p`` (s_q, s_p: one number for every coordinate, or a
    tuple of one per coordinate) and ``t`` (s_t), each in the user's units of its quantity.

    Per-coordinate scales keep Hamilton's equations only where every pair has one product s_q_i s_p_i
    (docs/python.md, "Scale your states"): checked here. A state in coordinates of ``'canonical'`` kind has
    column scales c = [s_q_i] + [s_p_i], one of ``'velocity'`` kind [s_q_i] + [s_q_i / s_t]; its time
    derivative has c / s_t; H has ``energy``."""
    q: float | tuple
    p: float | tuple
    t: float

    def __post_init__(self):
        for name in ("q", "p"):
            value = getattr(self, name)
            if isinstance(value, (list, tuple, np.ndarray)):
                object.__setattr__(self, name, tuple(float(v) for v in value))
        s_q, s_p = self.pairs(max(len(v) if isinstance(v, tuple) else 1 for v in (self.q, self.p)))
        product = s_q * s_p
        if not (np.all(product > 0) and np.all(np.isfinite(product)) and self.t > 0):
            raise ValueError(f"unit scales must be positive and finite, got q={self.q}, p={self.p}, t={self.t}")
        if np.abs(product / product[0] - 1).max() > _PRODUCT_RTOL:
            raise ValueError(f"per-coordinate unit scales must keep one product s_q_i * s_p_i (Hamilton's equations), "
                             f"got {product.tolist()}")

    @property
    def energy(self) -> float:
        """s_q s_p / s_t (the same for every pair): H = energy * H'."""
        s_q, s_p = self.pairs(1 if not isinstance(self.q, tuple) else len(self.q))
        return float(s_q[0] * s_p[0] / self.t)

    def pairs(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``(s_q, s_p)``, each ``(n,)`` float64: the scales of the n coordinate pairs."""
        return _per_pair(self.q, n, "q"), _per_pair(self.p, n, "p")

    def state(self, coordinates: str, dim: int) -> torch.Tensor:
        """The column scales c ``(dim,)``, float64, of a state in ``coordinates`` (x = c * x')."""
        s_q, s_p = self.pairs(dim // 2)
        second = s_q / self.t if coordinates in VELOCITY_LIKE else s_p
        return torch.as_tensor(np.concatenate([s_q, second]), dtype=torch.float64)

    def to_canonical(self, x, dxdt, coordinates: str) -> tuple[np.ndarray, np.ndarray]:
        """``(x', dx'/dt')``: states and their time derivatives ``(rows, dim)`` in the canonical units."""
        x, dxdt = _numpy(x), _numpy(dxdt)
        c = self.state(coordinates, x.shape[1]).numpy()
        return x / c, dxdt * self.t / c

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


def _one_scale_serves(blocks: list[np.ndarray]) -> bool:
    """Whether one scale per block (all q, all p, ...) serves: within each block the columns' RMS values
    lie within COLUMN_SPREAD of each other. A column of RMS 0 has no scale of its own: one scale serves then."""
    spreads = [_column_rms(block) for block in blocks]
    if any(not rms.min() > 0 for rms in spreads):
        return True
    return all(rms.max() / rms.min() <= COLUMN_SPREAD for rms in spreads)


def _pair_scales(n: int, rows: list[tuple[np.ndarray, float, float]]) -> tuple[np.ndarray, float, float]:
    """The log scales (a_i = log s_q_i, c = log s_q_i s_p_i, t = log s_t) that best make every column's
    RMS 1 in the least-squares sense of the logs: ``rows`` holds, per family of columns, their log RMS
    (``(n,)``) and how a_i, c enter its log scale: a family whose scale is s_q_i^u (s_q_i s_p_i)^v / s_t^w
    reads ``(log_rms, (u, v, w))``."""
    A, b = [], []
    for log_rms, (u, v, w) in rows:
        for i in range(n):
            row = np.zeros(n + 2)
            row[i], row[n], row[n + 1] = u, v, -w
            A.append(row)
            b.append(log_rms[i])
    solution = np.linalg.lstsq(np.asarray(A), np.asarray(b), rcond=None)[0]
    return solution[:n], float(solution[n]), float(solution[n + 1])


def fit_scales(x, dxdt, coordinates: str = "canonical", periodic: bool = False,
               per_pair: bool | None = None) -> UnitScales:
    """The scales of training states ``x`` and their ``dxdt`` ``(rows, 2n)`` in ``coordinates``.

    One scale for all q and one for all p where it serves: s_q the RMS of every q (1 for angles), s_p that
    of every p, s_t the geometric mean of s_q / rms(dq/dt) and s_p / rms(dp/dt), so q', p' and their
    rates are of size 1 (the ratio of the two rates is the system's own, for ``hnn.balance`` to weigh).
    On velocity-like states s_t = s_q / rms(qdot) and s_p = s_q / s_t (unit mass: a mass is not
    observable from velocities). Where one scale cannot serve (the RMS values of the q columns, the p
    columns or either half of ``dxdt`` spread over more than COLUMN_SPREAD: bodies of very different mass)
    and q are not angles, one s_q_i per coordinate with s_p_i = C / s_q_i (one product for every pair:
    Hamilton's equations hold) and one s_t, chosen so that the logs of every column's RMS in the new
    units are nearest 0 in the least-squares sense (on velocity-like states: of q, qdot and qddot, the
    velocities' scale s_q_i / s_t). ``per_pair`` True or False forces either. A ratio of the system's own
    time scales (a heavy body's slow swing beside a light one's fast one) is no unit: no choice of scales
    brings every column to size 1 then (docs/stress.md, the two masses)."""
    x, dxdt = _numpy(x), _numpy(dxdt)
    if x.ndim != 2 or x.shape[1] % 2 or x.shape != dxdt.shape:
        raise ValueError(f"x and dxdt must have one shape (rows, 2n), got {x.shape} and {dxdt.shape}")
    n = x.shape[1] // 2
    if coordinates not in VELOCITY_LIKE + CANONICAL_LIKE:
        raise ValueError(f"--units reads states of q and p or q and qdot; these are {coordinates!r}: use --units off")
    halves = [x[:, :n], x[:, n:], dxdt[:, :n], dxdt[:, n:]]
    names = ("q", "qdot" if coordinates in VELOCITY_LIKE else "p", "dq/dt", "dp/dt")
    # on velocity-like states dq/dt is the state's own second half: the parts are q, qdot and qddot
    parts = halves if coordinates in CANONICAL_LIKE else [halves[0], halves[1], halves[3]]
    if per_pair is None:
        per_pair = not (periodic or n == 1 or _one_scale_serves(parts))
    if not per_pair or periodic:
        s_q = 1.0 if periodic else _rms(x[:, :n], "q")
        if coordinates in VELOCITY_LIKE:
            s_v = _rms(x[:, n:], "qdot")
            return UnitScales(s_q, s_v, s_q / s_v)
        s_p = _rms(x[:, n:], "p")
        rate_q, rate_p = _rms(dxdt[:, :n], "dq/dt"), _rms(dxdt[:, n:], "dp/dt")
        return UnitScales(s_q, s_p, float(np.sqrt(s_q / rate_q * s_p / rate_p)))
    logs = [np.log(_column_rms(h)) for h in halves]
    for log, name in zip(logs, names):
        if not np.isfinite(log).all():
            raise ValueError(f"--units: a column of {name} in the training data has RMS 0 or not finite, so it has "
                             "no scale to divide by; use --units off")
    if coordinates in VELOCITY_LIKE:      # q_i / s_q_i, qdot_i s_t / s_q_i and qddot_i s_t^2 / s_q_i of size 1
        a, _, t = _pair_scales(n, [(logs[0], (1, 0, 0)), (logs[1], (1, 0, 1)), (logs[3], (1, 0, 2))])
        s_q, s_t = np.exp(a), float(np.exp(t))
        product = float(np.exp(2 * a.mean())) / s_t        # a unit mass: s_p_i = product / s_q_i
        return UnitScales(tuple(s_q), tuple(product / s_q), s_t)
    # q_i / s_q_i, p_i / s_p_i, dq_i/dt s_t / s_q_i and dp_i/dt s_t / s_p_i of size 1, s_p_i = C / s_q_i
    a, c, t = _pair_scales(n, [(logs[0], (1, 0, 0)), (logs[1], (-1, 1, 0)), (logs[2], (1, 0, 1)),
                                     (logs[3], (-1, 1, 1))])
    s_q = np.exp(a)
    return UnitScales(tuple(s_q), tuple(np.exp(c) / s_q), float(np.exp(t)))


def sizes(x, dxdt=None, periodic: bool = False) -> dict[str, float]:
    """The RMS of q (unless angles), of p (or qdot) and of each half of ``dxdt`` (where given) over every
    column of each: what ``--units auto`` and ``hnn.train``'s warning read."""
    x = _numpy(x)
    n = x.shape[1] // 2
    parts = {"q": x[:, :n], "p": x[:, n:]}
    if periodic:
        del parts["q"]
    if dxdt is not None:
        dxdt = _numpy(dxdt)
        parts.update({"dq/dt": dxdt[:, :n], "dp/dt": dxdt[:, n:]})
    return {name: float(np.sqrt(np.mean(np.square(a)))) for name, a in parts.items()}


def far_from_unit(x, dxdt=None, periodic: bool = False) -> bool:
    """Whether the RMS of q (unless angles) or of p lies outside [1 / AUTO_FAR, AUTO_FAR] of its entry, or
    that of either half of ``dxdt`` outside its own (``--units auto`` rescales there). A part that is zero
    to float32's rounding of the largest (a free particle's dp/dt) has no size to judge."""
    found = sizes(x, dxdt, periodic)
    zero = np.finfo(np.float32).eps * max(found.values(), default=0.0)
    return any(not 1 / AUTO_FAR[name] <= s <= AUTO_FAR[name] for name, s in found.items() if s > zero)


def auto_bounds() -> str:
    """``'q and p within [0.1, 10], dq/dt and dp/dt within [0.01, 100]'``: AUTO_FAR in words."""
    return (f"q and p within [{1 / AUTO_FAR['q']:g}, {AUTO_FAR['q']:g}], dq/dt and dp/dt within "
            f"[{1 / AUTO_FAR['dq/dt']:g}, {AUTO_FAR['dq/dt']:g}]")


def describe_sizes(x, dxdt=None, periodic: bool = False) -> str:
    """``'q 0.001, p 1, dq/dt 0.001, dp/dt 1'``: the RMS sizes ``far_from_unit`` reads, for a message."""
    return ", ".join(f"{name} {value:.3g}" for name, value in sizes(x, dxdt, periodic).items())


def spreads(x, dxdt=None) -> dict[str, float]:
    """Per part (q, p, dq/dt, dp/dt where given) the largest over the smallest RMS of its columns; a part
    with a column of RMS 0 is left out (it has no scale of its own to take)."""
    x = _numpy(x)
    n = x.shape[1] // 2
    parts = {"q": x[:, :n], "p": x[:, n:]}
    if dxdt is not None:
        dxdt = _numpy(dxdt)
        parts.update({"dq/dt": dxdt[:, :n], "dp/dt": dxdt[:, n:]})
    out = {}
    for name, part in parts.items():
        rms = _column_rms(part)
        if rms.min() > 0:
            out[name] = float(rms.max() / rms.min())
    return out


def rescale_reason(x, dxdt=None, periodic: bool = False, coordinates: str = "canonical") -> str | None:
    """Why ``--units auto`` rescales states ``x`` and their ``dxdt`` in ``coordinates``, or None where it leaves
    them: their sizes lie outside its bounds (``far_from_unit``), or (unless angles, whose s_q stays 1) the
    columns of one part spread in size over COLUMN_SPREAD, which one scale cannot serve (a scale per coordinate
    pair can: ``fit_scales`` reads the same parts, q, qdot and qddot on velocity-like states)."""
    if far_from_unit(x, dxdt, periodic):
        return f"far from unit scale (RMS {describe_sizes(x, dxdt, periodic)}; auto leaves {auto_bounds()})"
    read = spreads(x, dxdt)
    if coordinates in VELOCITY_LIKE:        # dq/dt is qdot itself
        read.pop("dq/dt", None)
    wide = {} if periodic else {name: s for name, s in read.items() if s > COLUMN_SPREAD}
    if wide:
        return (f"of columns whose sizes spread over {COLUMN_SPREAD:g}x within one part ("
                + ", ".join(f"{name} {s:.3g}x" for name, s in wide.items()) + "), which one scale cannot serve")
    return None


def units_reason(mode: str, x, dxdt=None, periodic: bool = False, coordinates: str = "canonical") -> str | None:
    """Why a fit under ``--units mode`` rescales ``x`` and ``dxdt``, or None where it trains on them as they
    are: the one rule of a run (``run_scales``) and of ``hnn.train``. ``'on'``: always; ``'auto'``:
    ``rescale_reason``'s; ``'off'``: never."""
    if mode not in UNITS:
        raise ValueError(f"units={mode!r}: choose one of {', '.join(UNITS)}")
    if mode == "on":
        return "to be rescaled (units=on)"
    return rescale_reason(x, dxdt, periodic, coordinates) if mode == "auto" else None


def refusal(model) -> str | None:
    """Why ``model``'s state carries a unit the rescaling cannot move, or None: a constrained kind whose
    graph holds rod lengths in the user's units (one without tethers or links rescales), a pixel kind."""
    if model.coordinates == "latent":
        return _PIXELS
    graph = getattr(model, "graph", None)
    if graph is not None and graph.count:
        return "its constraint graph holds lengths in the data's units"
    if getattr(model, "bodies", None) is not None:     # the pair kind: scales per column would bend its distances
        return "it reads distances between bodies, which scales per column would distort"
    return None


def check_supported(model: Model) -> None:
    """A ValueError naming the fix for a model whose state carries a unit the rescaling cannot move."""
    why = refusal(model)
    if why is not None:
        raise ValueError(f"--units rescales q, p and t, and the {type(model).__name__} cannot be rescaled: "
                         f"{why}. Use --units off (and give the data in units near 1)")


class Rescaled(Model):
    """``inner`` (a model of the canonical coordinates x' = x / c, t' = t / s_t) in the user's units.

    Mirrors ``inner``'s declarations; ``time_derivative`` (c / s_t) f'(x / c), ``hamiltonian``
    energy * H'(x / c); the structure the solvers read through ``field`` (S, the exact discrete
    gradient, a separable model's halves) and a mechanical model's ``inverse_mass`` and ``potential``
    are mapped too, as are the observed coordinates of a model that ``maps`` them. ``inner``'s
    weights are its state dict's (``inner.``-prefixed); the scales are its extra state, so a saved
    state dict carries them.

    ``scales=None``: to be fit from the training data by the first ``hnn.train`` (its ``units``), the
    notebook's way to train in canonical units and get a model that answers in the user's:

        model = hnn.units.Rescaled(hnn.MechanicalHNN(2, 64))
        hnn.train(model, x, dxdt)            # scales fit from x, dxdt; inner trained in x / c, t / s_t
        model.inverse_mass(q)                # the user's units
    """

    def __init__(self, inner: Model, scales: UnitScales | None = None):
        super().__init__()
        check_supported(inner)
        self.inner = inner
        self.input_dim = inner.input_dim
        for name in ("coordinates", "takes", "maps", "conservative", "separable", "dissipative"):
            setattr(self, name, getattr(inner, name))
        # own state's columns; an observed state's (where inner maps [q, qdot] into [q, p]); on inner's dtype and device
        like = next(inner.parameters(), torch.empty(0, dtype=torch.float64))
        self.register_buffer("_own", torch.ones(inner.input_dim).to(like), persistent=False)
        self.register_buffer("_seen", torch.ones(inner.input_dim).to(like), persistent=False)
        self.scales = None
        if scales is not None:
            self.set_scales(scales)

    def set_scales(self, scales: UnitScales) -> None:
        """Fix the scales (``hnn.train`` does, from the training data, for a model made without them)."""
        self.scales = scales if isinstance(scales, UnitScales) else UnitScales(**scales)
        self._own = self.scales.state(self.inner.coordinates, self.input_dim).to(self._own)
        self._seen = self.scales.state("velocity", self.input_dim).to(self._seen)

    def get_extra_state(self) -> dict:
        return {} if self.scales is None else self.scales.to_dict()

    def set_extra_state(self, state: dict) -> None:
        if state:
            self.set_scales(UnitScales(**state))

    def _apply(self, fn, *args, **kwargs):
        """``.to``, ``.double()``, ...: the scale columns made again from the exact float scales in the new
        dtype and device (cast from float32 they would carry its rounding into float64)."""
        out = super()._apply(fn, *args, **kwargs)
        if self.scales is not None:
            self.set_scales(self.scales)
        return out

    def _scaled(self) -> UnitScales:
        if self.scales is None:
            raise ValueError("this hnn.units.Rescaled has no scales yet: train it with hnn.train (which fits them "
                             "from the training data), or give them: Rescaled(model, hnn.units.fit_scales(x, dxdt))")
        return self.scales

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        """dx/dt ``(batch, dim)`` at user-unit states ``x`` ``(batch, dim)``, in user units."""
        return self.inner.time_derivative(x / self._own) * (self._own / self._scaled().t)

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H ``(batch,)`` in the user's units of energy (s_q s_p / s_t)."""
        return self.inner.hamiltonian(x / self._own) * self._scaled().energy

    def equation(self, digits: int = 4, frame=None) -> str:
        """A library fit's equation in the user's units: its scaling undone exactly (``hnn.fits.equation``);
        ``frame`` (an ``hnn.fits.Frame``) the user's columns, outside these scales."""
        from .fits.equations import Frame

        if not hasattr(self.inner, "equation"):
            raise ValueError(f"a {type(self.inner).__name__} is no library fit: it has no equation "
                             "(fit='library' or 'sindy')")
        frame = (frame or Frame.own(self.input_dim)).outside(self.scales, self.inner.coordinates)
        return self.inner.equation(digits=digits, frame=frame)

    def structure(self) -> torch.Tensor | None:
        inner = self.inner.structure()
        if inner is None:       # the canonical J: every pair has one product s_q_i s_p_i, so J stays J
            return None
        c, s = self._own.to(inner), self._scaled()
        return c[:, None] * inner * c[None, :] / (s.t * s.energy)

    def exact_discrete_gradient(self) -> Callable | None:
        inner = self.inner.exact_discrete_gradient()
        if inner is None:
            return None
        return lambda x0, x1: inner(x0 / self._own, x1 / self._own) * (self._scaled().energy / self._own)

    def _halves(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The own state's column scales ``(s_q, s_p)``, each ``(n,)``."""
        n = self.input_dim // 2
        return self._own[:n], self._own[n:]

    def kinetic_gradient(self, p: torch.Tensor) -> torch.Tensor:
        """dT/dp = dq/dt ``(batch, n)`` at momenta ``p`` ``(batch, n)``, user units."""
        s_q, s_p = self._halves()
        return self.inner.kinetic_gradient(p / s_p) * (s_q / self._scaled().t)

    def potential_gradient(self, q: torch.Tensor) -> torch.Tensor:
        """dV/dq = -dp/dt ``(batch, n)`` at positions ``q`` ``(batch, n)``, user units."""
        s_q, s_p = self._halves()
        return self.inner.potential_gradient(q / s_q) * (s_p / self._scaled().t)

    def inverse_mass(self, q: torch.Tensor) -> torch.Tensor:
        """A mechanical model's M^-1(q) ``(batch, n, n)`` = d2H/dp2, user units: S_q M'^-1 S_q / (s_t^2 energy)."""
        s_q, _ = self._halves()
        s = self._scaled()
        return self.inner.inverse_mass(q / s_q) * (s_q[:, None] * s_q[None, :] / (s.t ** 2 * s.energy))

    def potential(self, q: torch.Tensor) -> torch.Tensor:
        """A model's V(q) ``(batch,)``, user units of energy."""
        return self.inner.potential(q / self._halves()[0]) * self._scaled().energy

    def state_from_observed(self, z: torch.Tensor) -> torch.Tensor:
        return self.inner.state_from_observed(z / self._seen) * self._own

    def observed_from_state(self, x: torch.Tensor) -> torch.Tensor:
        return self.inner.observed_from_state(x / self._own) * self._seen

    def observed_time_derivative(self, z: torch.Tensor) -> torch.Tensor:
        return self.inner.observed_time_derivative(z / self._seen) * (self._seen / self._scaled().t)


def in_canonical_units(model, units: str, x, dxdt, test_x=None, test_dxdt=None, caller: str = "hnn.train") -> tuple:
    """``(the model to fit, x, dxdt, test_x, test_dxdt)`` of a fit of dx/dt under ``units`` (``hnn.train``'s and
    ``hnn.fit_least_squares``' one rule, ``caller`` naming which in its message): an ``Rescaled`` model's inner
    and the arrays in its canonical units (its scales fit here from ``x``, ``dxdt`` where it has none: by
    ``units``' rule, 1 where the rule leaves the data as they are); any other model and the arrays
    themselves, or a ValueError where ``units`` would rescale them (a plain model cannot answer back in the
    user's units)."""
    inner = getattr(model, "inner", model)
    periodic = bool(getattr(inner, "periodic", False))
    coordinates = "velocity" if getattr(inner, "coordinates", "canonical") in VELOCITY_LIKE else "canonical"
    reason = units_reason(units, x, dxdt, periodic, coordinates)      # a run's rule (run_scales') too
    if not isinstance(model, Rescaled):
        if reason is not None:
            verb = "train" if caller == "hnn.train" else "fit"
            raise ValueError(f"units={units!r}: x and dxdt are {reason}, where a fit "
                             f"goes wrong, and {type(model).__name__} answers in the units it is fit in: {verb} "
                             f"hnn.units.Rescaled(model) instead ({caller} fits its scales from these data, {verb}s the "
                             f"model in them and it answers in yours), or pass units='off' to {verb} on them as they are")
        return model, x, dxdt, test_x, test_dxdt
    if model.scales is None:
        model.set_scales(fit_scales(x, dxdt, coordinates, periodic) if reason is not None else UnitScales(1.0, 1.0, 1.0))
    pairs = [model.scales.to_canonical(a, b, coordinates) if a is not None else (a, b)
             for a, b in ((x, dxdt), (test_x, test_dxdt))]
    return (model.inner, *pairs[0], *pairs[1])


def _arrays(dataset: dict, arrays) -> tuple:
    return tuple(dataset[key] for key in arrays)


def sized_arrays(dataset: dict, objective) -> tuple:
    """``(states, their dx/dt or None)`` whose sizes ``--units auto`` reads: a fit of dx/dt's training
    pair, or a path objective's states (and the dataset's dx/dt where it has one and the objective reads
    rates: a learned map's loss holds no rate and no time, ``Objective.reads_rates``, so the unit of the data's
    time cannot move its fit and only its states' sizes are judged)."""
    if objective.fits_derivative:
        return _arrays(dataset, objective.arrays[:2])
    return dataset.get("x"), dataset.get("dxdt") if objective.reads_rates else None


def run_scales(mode: str, kind: str, dataset: dict, objective, model: Model) -> UnitScales | None:
    """The scales a run with ``--units mode`` trains its (untrained) ``model`` of ``kind`` in on ``dataset``, or
    None (``units='off'``, or ``'auto'`` on data near unit scale, whatever the kind and objective); a
    ValueError naming the fix where the rescaling would apply to an objective or a kind it does not
    support (``'on'``, or ``'auto'`` on data far from unit scale). A model that reads its q as angles
    (``model.periodic``) keeps s_q = 1. The pixel kinds read pixels, of no unit: ``'auto'`` leaves them."""
    if mode not in UNITS:
        raise ValueError(f"units={mode!r}: choose one of {', '.join(UNITS)}")
    if mode == "off" or (mode == "auto" and model.coordinates == "latent"):
        return None
    periodic = bool(getattr(model, "periodic", False))
    x, dxdt = sized_arrays(dataset, objective)
    why = f"--units {mode}"
    if mode == "auto":
        reason = None if x is None else units_reason(mode, x, dxdt, periodic, observed_coordinates(dataset))
        if reason is None:
            return None
        why = f"--units auto (the default) found the training data {reason}"
    if refusal(model) is not None:
        raise ValueError(f"{why}, and the {kind} kind cannot be rescaled: {refusal(model)}; give the data "
                         "in units near 1, or pass --units off to train on them as they are")
    if not objective.fits_derivative:
        raise ValueError(f"{why}, which rescales a fit of dx/dt (--objective derivative); the "
                         f"{type(objective).__name__} steps paths in the data's own time: give the data in units near "
                         "1, or pass --units off to train on them as they are")
    return fit_scales(x, dxdt, observed_coordinates(dataset), periodic)


def canonical_fit(model: Rescaled, dataset: dict, arrays) -> tuple[Model, dict]:
    """``(model.inner, dataset in its canonical units)``: what a rescaled run trains."""
    return model.inner, canonical_dataset(dataset, model.scales, arrays)


def canonical_dataset(dataset: dict, scales: UnitScales, arrays) -> dict:
    """``dataset`` with its ``arrays`` (states, their dx/dt, and the test pair) and its ``dt`` in the
    canonical units of ``scales``."""
    coordinates = observed_coordinates(dataset)
    out = dict(dataset)
    for xs, ys in (arrays[:2], arrays[2:]):
        out[xs], out[ys] = scales.to_canonical(dataset[xs], dataset[ys], coordinates)
    if "dt" in dataset:
        out["dt"] = float(dataset["dt"]) / scales.t
    return out


def wrap_saved(model: Model, args: dict) -> Model:
    """``model`` in ``Rescaled`` where a run's ``args`` record ``unit_scales`` (a rescaled run), else itself."""
    scales = args.get("unit_scales")
    return model if scales is None else Rescaled(model, UnitScales(**scales))
