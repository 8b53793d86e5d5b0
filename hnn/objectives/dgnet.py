"""DGNet's objective (Matsubara, Ishikawa & Yaguchi 2020): fit finite differences of observed paths
with the discrete gradient of the learned H between the two states.

For consecutive observed states x_n, x_{n+1} a time ``dt`` apart, the model predicts

    (x_{n+1} - x_n) / dt  ~  S grad-bar H(x_n, x_{n+1})

(the step of the ``'discrete_gradient'`` solver, read backwards): no time derivatives are needed,
and the model so trained rolls out with that solver to the same discrete-time dynamics it fit.
The loss is the squared error, averaged over components (DGNet's ``L2_loss``).

    python experiment-spring/train.py --objective discrete_gradient
    hnn.run_experiment(config, dataset, hnn.objectives.dgnet.DiscreteGradientObjective())

A dataset gives its paths as ``x`` and ``test_x`` (trajectory after trajectory, ``len(t_eval)``
states each) with their spacing ``dt``: ``prepare`` cuts every pair of consecutive states of a path
into one row ``[x_n, x_{n+1}]`` (all pairs, overlapping, as DGNet does). A model that maps the
observed coordinates into its own (``hnn.Model.maps``) is fit in its own state, both ends mapped.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from ..integrators.discrete_gradient import energy_parts, structured
from ..interface import EnergyField, declared
from . import PathObjective, cut_paths


def pairs_from_paths(rows, path_points: int) -> np.ndarray:
    """Every pair of consecutive states of each path, ``(paths * (path_points - 1), 2 * width)`` rows
    ``[x_n, x_{n+1}]``, from ``rows`` ``(paths * path_points, width)`` listed path after path."""
    rows = np.asarray(rows)
    if not (isinstance(path_points, int) and path_points >= 2):
        raise ValueError(f"paths need at least 2 states to give a pair, got {path_points!r}")
    if rows.ndim != 2 or len(rows) % path_points:
        raise ValueError(f"{len(rows)} rows are not whole paths of {path_points} states; the dataset must "
                         "list its trajectories one after another")
    paths = rows.reshape(-1, path_points, rows.shape[1])
    return np.ascontiguousarray(np.concatenate([paths[:, :-1], paths[:, 1:]], axis=2).reshape(-1, 2 * rows.shape[1]))


class DiscreteGradientObjective(PathObjective):
    """Fit ``(x1 - x0) / dt`` with ``S grad-bar H(x0, x1)`` on rows ``[x0, x1]`` of consecutive states.

    ``dt``: their spacing (default: the dataset's ``dt``). The model must declare ``conservative``:
    its ``field`` carries the H whose discrete gradient is fit (``hnn.interface.EnergyField``).
    """
    arrays = ("pairs", "pairs", "test_pairs", "test_pairs")

    def __init__(self, dt: float | None = None, observed: str = "canonical"):
        self.dt, self.observed = dt, observed

    def prepare(self, dataset: dict) -> dict:
        return cut_paths(dataset, ("pairs", "test_pairs"), pairs_from_paths, "the discrete-gradient objective")

    def loss_for(self, model: nn.Module, dt: float | None = None, observed: str | None = None):
        """``(x, y) -> (batch, width)`` squared errors for ``hnn.train``; ``y`` rows ``[x0, x1]`` (``x`` unused) of
        states in ``observed`` coordinates ``dt`` apart (default: this object's)."""
        dt = self.dt if dt is None else dt
        if dt is None or not (dt > 0 and np.isfinite(dt)):
            raise ValueError(f"the discrete-gradient objective needs the states' positive time step dt, got {dt!r}: "
                             "DiscreteGradientObjective(dt=...) or a dataset with 'dt'")
        model = declared(model)
        field = model.field
        if not isinstance(field, EnergyField) or field.hamiltonian is None:
            raise ValueError(f"the discrete-gradient objective fits S grad-bar H of a learned H, and "
                             f"{type(model).__name__} carries none (conservative={model.conservative}): choose a "
                             "conservative kind such as hnn, separable or mechanical")
        observed = self.observed if observed is None else observed
        model.relation(observed)        # a model that cannot read these states: one clear error

        def loss(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
            if y.shape[1] % 2:
                raise ValueError(f"pairs of {y.shape[1]} columns are not two states of one width")
            z0, z1 = y.chunk(2, dim=1)
            x0, x1 = model.state_from(z0, observed), model.state_from(z1, observed)
            dg, S = energy_parts(field, x0.shape[1], "the discrete-gradient objective")
            return ((x1 - x0) / dt - structured(dg(x0, x1), S)).pow(2)
        return loss

