"""The objective of a learned map (``hnn.models.maps``): its one step fit to the next observed state.

For consecutive observed states x_n, x_{n+1} the data's step ``dt`` apart, the loss of a row is the
squared error of ``model.step(x_n)`` against x_{n+1}, per component (jpzxshi/sympnets' MSE on its
pairs). No derivative and no integrator: a map trained so rolls out at the data's step and no other.

    python experiment-pend/train.py --model g_sympnet
    model = hnn.models.GSympNet(2, dt=0.1)             # the classes' defaults are the command's (tanh, 200, 4)
    hnn.train(model, pairs, pairs, loss=hnn.objectives.map.MapObjective(dt=0.1).loss_for(model))

A fit that ends no better than the identity map in q or in p on its own training pairs warns (``MapNotLearnedWarning``,
``warn_if_not_learned``), naming the fix; docs/maps.md has the recipe for your own pairs.

``prepare`` cuts every pair of consecutive states of each path (``x`` and ``test_x``, path after path,
``t_eval`` long, as ``hnn.objectives.dgnet.pairs_from_paths``) into a row ``[x_n, x_{n+1}]``, or, for a dataset of
timed rows instead of paths (``t``, ``test_t``: the real pendulum), pairs the rows one ``dt`` apart
(``pairs_from_times``; ``t_step``, where given, is that step in the units of ``t``: a measured file's
seconds, whose ``dt`` is in scaled time): a gap of several steps pairs nothing, and no pair at all is an
error. The map's step is the dataset's ``dt`` (``hnn.specs.ModelSpec.dt``); a map built with another step
is refused.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import torch
from torch import nn

from .dgnet import pairs_from_paths
from ..interface import declared
from . import LoopOptions, PathObjective, cut_paths
from ..specs import ObjectiveSpec

# how far two timed rows' spacing may be from dt to count as one step (times written to a few digits)
STEP_TOLERANCE = 1e-4


def pairs_from_times(rows, t, dt: float) -> np.ndarray:
    """Rows ``[x_i, x_{i+1}]`` ``(pairs, 2 * width)`` of the consecutive ``rows`` ``(N, width)`` whose times
    ``t`` ``(N,)`` are one step ``dt`` apart (within ``STEP_TOLERANCE`` of a step)."""
    rows, t = np.asarray(rows), np.asarray(t, dtype=np.float64)
    if rows.ndim != 2 or t.shape != (len(rows),):
        raise ValueError(f"timed rows need x (N, width) and t (N,), got {rows.shape} and {t.shape}")
    one = np.abs(np.diff(t) / dt - 1.0) <= STEP_TOLERANCE
    return np.ascontiguousarray(np.concatenate([rows[:-1][one], rows[1:][one]], axis=1))


def _check_pairs(dataset: dict, why: str) -> None:
    """A ValueError naming ``why`` where the train or the test ``pairs`` of ``dataset`` are none (a loss over no
    rows is nan, which would read as a diverged fit)."""
    empty = [name for name in ("pairs", "test_pairs") if not len(dataset[name])]
    if empty:
        raise ValueError(f"the map objective found no {' and no '.join(empty)} of consecutive states one step apart: "
                         f"{why}, so a learned map has nothing to learn from. Give rows at the data's own step (a "
                         "dataset's 't_step' is its step in the units of 't' where 'dt' is in others), or choose a "
                         "field kind (hnn, mechanical, ...)")


class MapObjective(PathObjective):
    """Fit ``model.step(x0)`` to ``x1`` on rows ``[x0, x1]`` of consecutive states ``dt`` apart; the
    model must be a learned map (``steps``) of that step. ``dt`` (default the dataset's)."""
    arrays = ("pairs", "pairs", "test_pairs", "test_pairs")
    # a map fits the state one step later to a state: no rate and no time enters its loss, so its fit is the same
    # whatever the unit of the data's time (a file's t in ms or in s pairs the same rows; ``hnn.units.sized_arrays``)
    reads_rates = False

    def __init__(self, dt: float | None = None, observed: str = "canonical"):
        self.dt, self.observed = dt, observed

    def prepare(self, dataset: dict) -> dict:
        if "t_eval" not in dataset and all(key in dataset for key in ("t", "test_t", "dt")):
            # the step in the units of t: a measured file's t is in its seconds and its dt in the scaled time
            # the model learns in (``t_step``: the same step in seconds); elsewhere the two share a unit
            step = float(dataset.get("t_step", dataset["dt"]))
            out = {**dataset, "pairs": pairs_from_times(dataset["x"], dataset["t"], step),
                   "test_pairs": pairs_from_times(dataset["test_x"], dataset["test_t"], step)}
            _check_pairs(out, f"its times t (train and test) hold no two consecutive rows one step {step:g} apart")
            return out
        if not all(key in dataset for key in ("dt", "t_eval")) and not all(key in dataset for key in self.arrays):
            raise ValueError("the map objective needs paths at a fixed step: this task's dataset gives neither paths "
                             "('dt' and 't_eval') nor timed rows ('t', 'test_t' and 'dt'), so a learned map has no "
                             "pairs to learn from; choose a field kind (hnn, mechanical, ...) for it")
        out = cut_paths(dataset, ("pairs", "test_pairs"), pairs_from_paths, "the map objective")
        _check_pairs(out, "its paths (t_eval) are shorter than two states")
        return out

    def train_options(self, model: nn.Module, spec: ObjectiveSpec, dataset: dict) -> LoopOptions:
        self._check_map(model, float(dataset["dt"]) if "dt" in dataset else self.dt)
        return super().train_options(model, spec, dataset)

    def _check_map(self, model: nn.Module, dt: float | None) -> None:
        """A ValueError unless ``model`` is a learned map whose step is ``dt`` (a map without one gets it; no
        ``dt``: the map's own)."""
        model = declared(model)
        if not model.steps:
            raise ValueError(f"the map objective fits a learned map's step, and {type(model).__name__} is a field "
                             "(steps=False): choose a map kind (g_sympnet, la_sympnet, henon) or another --objective")
        if dt is None and model.dt is None:
            raise ValueError("the map objective needs the pairs' time step: MapObjective(dt=...), a dataset with 'dt' "
                             "or a map built with its dt")
        if dt is None:
            return
        if model.dt is None:
            model.dt = float(dt)
        elif not math.isclose(model.dt, dt, rel_tol=1e-9):
            raise ValueError(f"this map's step is dt={model.dt:g} but its data are dt={dt:g} apart: a map learns the "
                             f"step of its data; build it with dt={dt:g}")

    def loss_for(self, model: nn.Module, dt: float | None = None, observed: str | None = None):
        """``(x, y) -> (batch, width)`` squared errors for ``hnn.train``; ``y`` rows ``[x0, x1]`` (``x`` unused),
        canonical states ``dt`` apart (``observed``: checked by ``train_options``, which refuses others)."""
        self._check_map(model, self.dt if dt is None else dt)
        return _StepLoss(model)


class MapNotLearnedWarning(UserWarning):
    """A trained map's step is no closer to its training pairs' next states than the identity map's, in q or in p."""


HALVES = ("q", "p")


def identity_errors(model: nn.Module, pairs) -> tuple[np.ndarray, np.ndarray]:
    """``(the map's, the identity map's)`` mean squared one-step errors ``(2,)``, of the q half and of the p half,
    over the rows ``[x_n, x_{n+1}]`` of ``pairs`` ``(rows, 2 * input_dim)``: ``model.step(x_n)``, and ``x_n``
    itself, against ``x_{n+1}``."""
    param, width = next(model.parameters()), model.input_dim
    y = torch.as_tensor(pairs, dtype=param.dtype, device=param.device)
    if y.dim() != 2 or y.shape[1] != 2 * width or not len(y):
        raise ValueError(f"pairs must be rows [x_n, x_(n+1)] of shape (rows >= 1, {2 * width}), got {tuple(y.shape)}")
    with torch.no_grad():
        step = torch.cat([model.step(part[:, :width]) for part in y.split(4096)])

    def halves(error: torch.Tensor) -> np.ndarray:
        return error.pow(2).reshape(len(y), 2, width // 2).mean(dim=(0, 2)).double().cpu().numpy()
    return halves(step - y[:, width:]), halves(y[:, :width] - y[:, width:])


def warn_if_not_learned(model: nn.Module, pairs, stacklevel: int = 2) -> None:
    """A ``MapNotLearnedWarning`` where ``model``'s step on its training ``pairs`` is no better than the identity
    map's in the q half or in the p half (``identity_errors``): a fit that learned nothing returns without a word
    otherwise. Each half is judged on its own, since a map that learned how q moves and left p where it was has
    the smaller error over the whole state (q's gain hides p's none) and rolls out as badly as one that learned
    nothing. A half that the identity already steps exactly (error 0: a free particle's momenta) has nothing
    to learn and is not judged."""
    error, identity = identity_errors(model, pairs)
    idle = [k for k in range(2) if identity[k] > 0 and not error[k] < identity[k]]
    if idle:
        said = "; ".join(f"in {HALVES[k]} {error[k]:.4g} against {identity[k]:.4g}" for k in idle)
        warnings.warn(MapNotLearnedWarning(
            f"this learned map's mean squared one-step error on its {len(pairs)} training pairs is no smaller than "
            f"the identity map's (x_(n+1) = x_n) {said}: it learned nothing of how "
            f"{' and '.join(HALVES[k] for k in idle)} moves. Train it as the commands do (the classes' defaults: "
            "tanh, width 200, 4 layers; learn_rate 1e-3 for 2000 steps or more), and check that each pair's states "
            "are one step dt apart (docs/maps.md, 'Train a map on your own pairs')"), stacklevel=stacklevel)


class _StepLoss:
    """``(x, y) -> (batch, width)`` squared errors of ``model.step`` on rows ``y = [x0, x1]`` (``x`` unused);
    once ``hnn.train`` ends, ``warn_if_not_learned`` on the training rows."""

    def __init__(self, model: nn.Module):
        self.model, self.width = model, model.input_dim

    def __call__(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        if y.shape[1] != 2 * self.width:
            raise ValueError(f"pairs of {y.shape[1]} columns are not two states of width {self.width}")
        return (self.model.step(y[:, :self.width]) - y[:, self.width:]).pow(2)

    def after_training(self, x: torch.Tensor, y: torch.Tensor) -> None:
        warn_if_not_learned(self.model, y, stacklevel=4)      # at the caller of hnn.train
