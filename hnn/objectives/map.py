"""The objective of a learned map (``hnn.models.maps``): its one step fit to the next observed state.

For consecutive observed states x_n, x_{n+1} the data's step ``dt`` apart, the loss of a row is the
squared error of ``model.step(x_n)`` against x_{n+1}, per component (jpzxshi/sympnets' MSE on its
pairs). No derivative and no integrator: a map trained so rolls out at the data's step and no other.

    python experiment-pend/train.py --model g_sympnet
    hnn.train(model, pairs, pairs, loss=hnn.objectives.map.MapObjective(dt=0.1).loss_for(model))

``prepare`` cuts every pair of consecutive states of each path (``x`` and ``test_x``, path after path,
``t_eval`` long, as ``hnn.objectives.dgnet.pairs_from_paths``) into a row ``[x_n, x_{n+1}]``, or, for a dataset of
timed rows instead of paths (``t``, ``test_t``: the real pendulum), pairs the rows one ``dt`` apart
(``pairs_from_times``): a gap of several steps pairs nothing. The map's step is the dataset's ``dt``
(``hnn.specs.ModelSpec.dt``); a map built with another step is refused.
"""
from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from .dgnet import pairs_from_paths
from ..interface import declared
from . import FitOptions, PathObjective, cut_paths
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


class MapObjective(PathObjective):
    """Fit ``model.step(x0)`` to ``x1`` on rows ``[x0, x1]`` of consecutive states ``dt`` apart; the
    model must be a learned map (``steps``) of that step. ``dt`` (default the dataset's)."""
    arrays = ("pairs", "pairs", "test_pairs", "test_pairs")

    def __init__(self, dt: float | None = None, observed: str = "canonical"):
        self.dt, self.observed = dt, observed

    def prepare(self, dataset: dict) -> dict:
        if "t_eval" not in dataset and all(key in dataset for key in ("t", "test_t", "dt")):
            dt = float(dataset["dt"])
            return {**dataset, "pairs": pairs_from_times(dataset["x"], dataset["t"], dt),
                    "test_pairs": pairs_from_times(dataset["test_x"], dataset["test_t"], dt)}
        if not all(key in dataset for key in ("dt", "t_eval")) and not all(key in dataset for key in self.arrays):
            raise ValueError("the map objective needs paths at a fixed step: this task's dataset gives neither paths "
                             "('dt' and 't_eval') nor timed rows ('t', 'test_t' and 'dt'), so a learned map has no "
                             "pairs to learn from; choose a field kind (hnn, mechanical, ...) for it")
        return cut_paths(dataset, ("pairs", "test_pairs"), pairs_from_paths, "the map objective")

    def train_options(self, model: nn.Module, spec: ObjectiveSpec, dataset: dict) -> FitOptions:
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
        width = model.input_dim

        def loss(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
            if y.shape[1] != 2 * width:
                raise ValueError(f"pairs of {y.shape[1]} columns are not two states of width {width}")
            return (model.step(y[:, :width]) - y[:, width:]).pow(2)
        return loss
