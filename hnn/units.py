"""Unit invariance: a run trains in canonical units of its own data, and its saved model answers in the user's.

    scales = hnn.units.fit_scales(x, dxdt, "canonical")        # s_q, s_p, s_t from the training data
    model = hnn.units.Rescaled(inner, scales)                  # inner reads q' = q / s_q, p' = p / s_p, t' = t / s_t
    hnn.train(inner, *scales.to_canonical(x, dxdt, "canonical"))   # train in those coordinates
    model.time_derivative(x)                                   # dx/dt in the user's units

The rescaling keeps Hamilton's equations: with q' = q / s_q, p' = p / s_p and t' = t / s_t the
flow of H is the flow of H' = H s_t / (s_q s_p) in the primed coordinates, so a model of H'
is a model of H = ``energy`` H'(x / c), c = [s_q .. s_p ..], ``energy`` = s_q s_p / s_t. One s_q for
every position and one s_p for every momentum (per-coordinate scales would need s_q_i s_p_i equal
for all i to keep one H): a change of units of all q, all p or t is undone exactly, since the scales
are RMS values of the data, which scale with them. Angles (``periodic``) keep s_q = 1: a network
that reads cos q, sin q fixes the radian.

Fit on states ``[q, qdot]`` (``'velocity'``, ``'cartesian'``) the momentum scale is s_q / s_t (unit
mass: a mass is not observable from velocities) and s_t makes the velocities' RMS 1.

``--units`` (``hnn.RunConfig.units``): ``off`` (the default: every published run trains in its
data's units, bit for bit as before), ``on`` (always) or ``auto`` (where the RMS of q, p, dq/dt or
dp/dt lies outside [1 / AUTO_FAR, AUTO_FAR]). A rescaled run records ``unit_scales`` in its
args.json; ``hnn.kinds.model_from_args`` wraps the rebuilt model in ``Rescaled`` from them, so
``hnn.load_run`` answers in the user's units. Such a run's loss history (metrics.json's ``history``), its
``loss_weights`` and any ``input_noise`` are in the canonical units; its final train and test losses are
the saved model's, in the user's. It trains alone, never in a group (``hnn.group_runs.unit_key``).

Supported: fits of dx/dt (``--objective derivative``, with or without ``--use_rk4``, whose dt is
rescaled too) of every kind that reads [q, p] or [q, qdot]: hnn, baseline, separable, dissipative,
mechanical (on [q, p], or mapping observed [q, qdot]), second_order and lagrangian. Refused, with a
ValueError naming ``--units off``: the constrained kinds (their constraint graph holds rod lengths in
the user's units, which the model does not rescale), the pixel kinds (no q and p to scale) and the path
objectives (trajectory, discrete_gradient: their snippets step the data's own time; not built yet).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
import torch

from .interface import Model
from .names import UNITS
from .objectives import DerivativeObjective, observed_coordinates

# 'auto' rescales where the RMS of q, p, dq/dt or dp/dt lies outside [1 / AUTO_FAR, AUTO_FAR]. The tasks'
# default data lie inside (measured: spring 0.45-0.90, pend 1.3-2.6, real 0.82-0.88, 2body 0.11-1.1,
# 3body 0.56-1.6, arm 1.7-8.2), so 'auto' trains each as 'off' does; at 10^-3 and 10^3 the stress
# study's cells without the rescaling degrade (docs/stress.md), with it they work. 'on' is not the
# default: its scales are never exactly 1, so it would move every published number.
AUTO_FAR = 10.0
# the state coordinates whose second half is a velocity (its scale s_q / s_t), and those it is a momentum
VELOCITY_LIKE = ("velocity", "cartesian")
CANONICAL_LIKE = ("canonical",)
# kinds whose states carry a scale of their own: the constrained kinds' graph holds rod lengths in the
# user's units, the pixel kinds read pixels and learn their own latent
_REFUSED = {"cartesian_canonical": "its constraint graph holds lengths in the data's units",
            "latent": "it reads pixels, not q and p (its latent coordinates are learned, of no unit)"}


def _numpy(a) -> np.ndarray:
    """``a`` (an array or a tensor) as a float64 array."""
    return np.asarray(a.detach().cpu() if torch.is_tensor(a) else a, dtype=np.float64)


def _rms(a: np.ndarray, name: str) -> float:
    value = float(np.sqrt(np.mean(np.square(a, dtype=np.float64))))
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"--units: the RMS of {name} in the training data is {value}, so it has no scale to "
                         "divide by; use --units off")
    return value


@dataclass(frozen=True)
class UnitScales:
    """The canonical rescaling of a run: ``q``, ``p``, ``t`` (s_q, s_p, s_t), in the user's units of each.

    A state in coordinates of ``'canonical'`` kind has column scales c = [s_q]*n + [s_p]*n, one of
    ``'velocity'`` kind [s_q]*n + [s_q / s_t]*n; its time derivative has c / s_t; H has ``energy``."""
    q: float
    p: float
    t: float

    @property
    def energy(self) -> float:
        """s_q s_p / s_t: H = energy * H'."""
        return self.q * self.p / self.t

    def state(self, coordinates: str, dim: int) -> torch.Tensor:
        """The column scales c ``(dim,)``, float64, of a state in ``coordinates`` (x = c * x')."""
        n = dim // 2
        second = self.q / self.t if coordinates in VELOCITY_LIKE else self.p
        return torch.tensor([self.q] * n + [second] * n, dtype=torch.float64)

    def to_canonical(self, x, dxdt, coordinates: str) -> tuple[np.ndarray, np.ndarray]:
        """``(x', dx'/dt')``: states and their time derivatives ``(rows, dim)`` in the canonical units."""
        x, dxdt = _numpy(x), _numpy(dxdt)
        c = self.state(coordinates, x.shape[1]).numpy()
        return x / c, dxdt * self.t / c

    def to_dict(self) -> dict:
        return asdict(self)


def fit_scales(x, dxdt, coordinates: str = "canonical", periodic: bool = False) -> UnitScales:
    """The scales of training states ``x`` and their ``dxdt`` ``(rows, 2n)`` in ``coordinates``: s_q the
    RMS of every q (1 for angles), s_p that of every p, s_t the geometric mean of s_q / rms(dq/dt) and
    s_p / rms(dp/dt), so q', p' and their rates are of size 1 (the ratio of the two rates is the
    system's own, for ``hnn.balance`` to weigh). On velocity-like states s_t = s_q / rms(qdot)."""
    x, dxdt = _numpy(x), _numpy(dxdt)
    if x.ndim != 2 or x.shape[1] % 2 or x.shape != dxdt.shape:
        raise ValueError(f"x and dxdt must have one shape (rows, 2n), got {x.shape} and {dxdt.shape}")
    n = x.shape[1] // 2
    s_q = 1.0 if periodic else _rms(x[:, :n], "q")
    if coordinates in VELOCITY_LIKE:
        s_v = _rms(x[:, n:], "qdot")
        return UnitScales(s_q, s_v, s_q / s_v)
    if coordinates not in CANONICAL_LIKE:
        raise ValueError(f"--units reads states of q and p or q and qdot; these are {coordinates!r}: use --units off")
    s_p = _rms(x[:, n:], "p")
    rate_q, rate_p = _rms(dxdt[:, :n], "dq/dt"), _rms(dxdt[:, n:], "dp/dt")
    return UnitScales(s_q, s_p, float(np.sqrt(s_q / rate_q * s_p / rate_p)))


def far_from_unit(x, dxdt, periodic: bool = False) -> bool:
    """Whether the RMS of q (unless angles), of p and of either half of ``dxdt`` lies outside
    [1 / AUTO_FAR, AUTO_FAR] (``--units auto`` rescales there)."""
    x, dxdt = _numpy(x), _numpy(dxdt)
    n = x.shape[1] // 2
    parts = ([] if periodic else [x[:, :n]]) + [x[:, n:], dxdt[:, :n], dxdt[:, n:]]
    sizes = [float(np.sqrt(np.mean(np.square(a)))) for a in parts]
    return any(not 1 / AUTO_FAR <= s <= AUTO_FAR for s in sizes)


def check_supported(model: Model) -> None:
    """A ValueError naming the fix for a model whose state carries a unit the rescaling cannot move."""
    if model.coordinates in _REFUSED:
        raise ValueError(f"--units rescales q, p and t, and the {type(model).__name__} cannot be rescaled: "
                         f"{_REFUSED[model.coordinates]}. Use --units off (and give the data in units near 1)")


class Rescaled(Model):
    """``inner`` (a model of the canonical coordinates x' = x / c, t' = t / s_t) in the user's units.

    Mirrors ``inner``'s declarations; ``time_derivative`` (c / s_t) f'(x / c), ``hamiltonian``
    energy * H'(x / c); the structure the solvers read through ``field`` (S, the exact discrete
    gradient, a separable model's halves) and a mechanical model's ``inverse_mass`` and ``potential``
    are mapped too, as are the observed coordinates of a model that ``maps`` them. ``inner``'s
    weights are its state dict's (``inner.``-prefixed)."""

    def __init__(self, inner: Model, scales: UnitScales):
        super().__init__()
        check_supported(inner)
        self.inner, self.scales = inner, scales
        self.input_dim = inner.input_dim
        for name in ("coordinates", "takes", "maps", "conservative", "separable", "dissipative"):
            setattr(self, name, getattr(inner, name))
        # own state's columns; an observed state's (where inner maps [q, qdot] into [q, p]); on inner's dtype and device
        like = next(inner.parameters(), torch.empty(0, dtype=torch.float64))
        self.register_buffer("_own", scales.state(inner.coordinates, inner.input_dim).to(like), persistent=False)
        self.register_buffer("_seen", scales.state("velocity", inner.input_dim).to(like), persistent=False)

    def _apply(self, fn, *args, **kwargs):
        """``.to``, ``.double()``, ...: the scale columns made again from the exact float scales in the new
        dtype and device (cast from float32 they would carry its rounding into float64)."""
        out = super()._apply(fn, *args, **kwargs)
        self._own = self.scales.state(self.inner.coordinates, self.input_dim).to(self._own)
        self._seen = self.scales.state("velocity", self.input_dim).to(self._seen)
        return out

    def time_derivative(self, x: torch.Tensor, t=None) -> torch.Tensor:
        """dx/dt ``(batch, dim)`` at user-unit states ``x`` ``(batch, dim)``, in user units."""
        return self.inner.time_derivative(x / self._own) * (self._own / self.scales.t)

    def hamiltonian(self, x: torch.Tensor) -> torch.Tensor:
        """H ``(batch,)`` in the user's units of energy (s_q s_p / s_t)."""
        return self.inner.hamiltonian(x / self._own) * self.scales.energy

    def structure(self) -> torch.Tensor | None:
        inner = self.inner.structure()
        if inner is None:       # the canonical J: every q has s_q, every p s_p, so J stays J
            return None
        c = self._own.to(inner)
        return c[:, None] * inner * c[None, :] / (self.scales.t * self.scales.energy)

    def exact_discrete_gradient(self) -> Callable | None:
        inner = self.inner.exact_discrete_gradient()
        if inner is None:
            return None
        return lambda x0, x1: inner(x0 / self._own, x1 / self._own) * (self.scales.energy / self._own)

    def kinetic_gradient(self, p: torch.Tensor) -> torch.Tensor:
        """dT/dp = dq/dt ``(batch, n)`` at momenta ``p`` ``(batch, n)``, user units."""
        return self.inner.kinetic_gradient(p / self.scales.p) * (self.scales.q / self.scales.t)

    def potential_gradient(self, q: torch.Tensor) -> torch.Tensor:
        """dV/dq = -dp/dt ``(batch, n)`` at positions ``q`` ``(batch, n)``, user units."""
        return self.inner.potential_gradient(q / self.scales.q) * (self.scales.p / self.scales.t)

    def inverse_mass(self, q: torch.Tensor) -> torch.Tensor:
        """A mechanical model's M^-1(q) ``(batch, n, n)`` = d2H/dp2, user units."""
        return self.inner.inverse_mass(q / self.scales.q) * (self.scales.q / (self.scales.t * self.scales.p))

    def potential(self, q: torch.Tensor) -> torch.Tensor:
        """A model's V(q) ``(batch,)``, user units of energy."""
        return self.inner.potential(q / self.scales.q) * self.scales.energy

    def state_from_observed(self, z: torch.Tensor) -> torch.Tensor:
        return self.inner.state_from_observed(z / self._seen) * self._own

    def observed_from_state(self, x: torch.Tensor) -> torch.Tensor:
        return self.inner.observed_from_state(x / self._own) * self._seen

    def observed_time_derivative(self, z: torch.Tensor) -> torch.Tensor:
        return self.inner.observed_time_derivative(z / self._seen) * (self._seen / self.scales.t)


def _arrays(dataset: dict, arrays) -> tuple:
    return tuple(dataset[key] for key in arrays)


def run_scales(mode: str, kind: str, dataset: dict, objective, model: Model) -> UnitScales | None:
    """The scales a run with ``--units mode`` trains its (untrained) ``model`` of ``kind`` in on ``dataset``, or
    None (``units='off'``, or ``'auto'`` on data near unit scale); a ValueError naming the fix for an
    objective or a kind it does not support. A model that reads its q as angles (``model.periodic``)
    keeps s_q = 1."""
    if mode not in UNITS:
        raise ValueError(f"units={mode!r}: choose one of {', '.join(UNITS)}")
    if mode == "off":
        return None
    if model.coordinates in _REFUSED:
        raise ValueError(f"--units {mode}: the {kind} kind cannot be rescaled, "
                         f"{_REFUSED[model.coordinates]}; use --units off")
    if not isinstance(objective, DerivativeObjective):
        raise ValueError(f"--units {mode} rescales a fit of dx/dt (--objective derivative); the "
                         f"{type(objective).__name__} steps paths in the data's own time: use --units off")
    x, dxdt = _arrays(dataset, objective.arrays[:2])
    periodic = bool(getattr(model, "periodic", False))
    if mode == "auto" and not far_from_unit(x, dxdt, periodic):
        return None
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
