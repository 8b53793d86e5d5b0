"""Trajectory training: fit a model by rolling it out over short snippets of observed paths.

The derivative objective needs dx/dt at every state; measured trajectories give states only.
Here the model is rolled out from each snippet's first state by a differentiable fixed-step
integrator, one step (or ``substeps``) per observation interval ``dt``, and the predicted
states are compared with the observed ones (mean absolute error, as Finzi et al. 2020, or
squared error):

    python experiment-spring/train.py --objective trajectory --snippet_steps 4   # any task with paths
    loss = hnn.objectives.trajectory.snippet_loss(model, snippets, dt)      # snippets (batch, points, 2n)
    hnn.train(model, flat, flat, loss=hnn.objectives.trajectory.TrajectoryObjective().loss_for(model, dt))

A run with ``objective='trajectory'`` (``hnn.RunConfig``) cuts its task's paths (``x`` and
``test_x``, path after path, ``t_eval`` long) into non-overlapping snippets of
``snippet_steps + 1`` states. The dataset's states are in the coordinates it declares
(``dataset["state"]``); a model that maps them into its own (``hnn.Model.maps``, e.g.
``hnn.MechanicalHNN``: [q, qdot] <-> [q, p]) is rolled out in its own state and compared after
mapping back; a model that reads them as they are rolls them out itself.

The integrator defaults to ``rk4``, and to ``leapfrog`` for a model that declares ``separable``
(``hnn.SeparableHNN``): symplectic for it at two field calls a step. A method that
``hnn.SOLVERS`` declares ``needs_separable`` is refused for other models.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from ..integrators.integrate import rollout
from ..interface import declared
from . import PathObjective, cut_paths
from ..integrators.solvers import SOLVERS, get_solver
from ..settings import RunSettings

SNIPPET_LOSSES = ("mae", "l2")


def default_method(model: nn.Module) -> str:
    """``'leapfrog'`` for a model that declares ``separable``, else ``'rk4'``."""
    return "leapfrog" if declared(model).separable else "rk4"


def check_method(method: str, model: nn.Module) -> None:
    """Raise ValueError unless ``method`` is a fixed-step solver valid for ``model``'s field."""
    solver = get_solver(method)
    if solver.adaptive:
        fixed = sorted(name for name, s in SOLVERS.items() if not s.adaptive)
        raise ValueError(f"trajectory training steps through a fixed-step method; {method!r} is not one "
                         f"(choose one of {fixed})")
    if solver.needs_separable and not declared(model).separable:
        raise ValueError(f"{method!r} is exact only for a separable H = T(p) + V(q), and "
                         f"{type(model).__name__} is not separable; use method='rk4' or 'midpoint'")


def rollout_observed(model: nn.Module, z0: torch.Tensor, t_eval, observed: str, method: str = "dopri5",
                     **options) -> torch.Tensor:
    """Observed states ``(batch, len(t_eval), width)`` of ``model`` rolled out by ``hnn.rollout``
    from observed starts ``z0`` ``(batch, width)`` in ``observed`` coordinates (a key of
    ``hnn.interface.COORDINATES``), in the model's own state between the maps; for evaluation
    (no autograd graph is kept)."""
    declared(model)
    with torch.no_grad():
        xs = rollout(model.field, model.state_from(z0, observed), t_eval, method=method, threads=None, **options)
        return model.observed_from(xs.reshape(-1, xs.shape[-1]), observed).reshape(xs.shape)


def rollout_snippet(model: nn.Module, z0: torch.Tensor, points: int, dt: float, method: str | None = None,
                    substeps: int = 1, observed: str = "canonical") -> torch.Tensor:
    """Predicted observed states ``(batch, points, width)`` from ``z0`` ``(batch, width)``, ``dt`` apart.

    Differentiable in the model's parameters: ``hnn.rollout(..., differentiable=True)`` with the
    method's fixed step ``dt / substeps``; a blow-up raises ``hnn.DivergenceError`` naming the rows.
    """
    if not (isinstance(points, int) and points >= 2):
        raise ValueError(f"a snippet needs points >= 2 (the start and at least one more), got {points!r}")
    if not (isinstance(substeps, int) and substeps >= 1):
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    if not (dt > 0 and np.isfinite(dt)):
        raise ValueError(f"dt must be a positive finite time step, got {dt!r}")
    method = method or default_method(model)
    check_method(method, model)
    xs = rollout(model.field, model.state_from(z0, observed), dt * np.arange(points), method=method,
                 differentiable=True, threads=None, dt=dt / substeps)
    return model.observed_from(xs.reshape(-1, xs.shape[-1]), observed).reshape(xs.shape)


def snippet_loss(model: nn.Module, snippets: torch.Tensor, dt: float, method: str | None = None,
                 loss: str = "mae", substeps: int = 1, start: torch.Tensor | None = None,
                 observed: str = "canonical") -> torch.Tensor:
    """Per-snippet error ``(batch,)`` of the model rolled out from each snippet's first state.

    ``snippets`` ``(batch, points, width)`` are observed states ``dt`` apart; ``start`` (default
    ``snippets[:, 0]``) is where the rollout begins (e.g. a noisy copy). ``observed``: the
    snippets' coordinates, mapped into the model's own where it declares the map (``hnn.Model``).
    The error is the mean
    over points 1.. and components of |z^ - z| (``'mae'``) or (z^ - z)^2 (``'l2'``); CHNN's MAE
    also averages in point 0, where the error is zero, so theirs is (points-1)/points of ours.
    """
    if loss not in SNIPPET_LOSSES:
        raise ValueError(f"unknown snippet loss {loss!r}; choose one of {SNIPPET_LOSSES}")
    if snippets.dim() != 3:
        raise ValueError(f"snippets must have shape (batch, points, width), got {tuple(snippets.shape)}")
    z0 = snippets[:, 0] if start is None else start
    pred = rollout_snippet(model, z0, snippets.shape[1], dt, method, substeps, observed)
    error = pred[:, 1:] - snippets[:, 1:]
    return (error.abs() if loss == "mae" else error.pow(2)).mean(dim=(1, 2))


def sample_snippets(paths, points: int, generator: torch.Generator) -> torch.Tensor:
    """One snippet of ``points`` consecutive states per path, as CHNN draws them: each path
    ``(batch, T, width)`` is cut into ``T // points`` non-overlapping pieces and one piece is
    chosen uniformly. Returns ``(batch, points, width)``."""
    paths = paths if torch.is_tensor(paths) else torch.as_tensor(paths, device="cpu")
    if paths.dim() != 3:
        raise ValueError(f"paths must have shape (batch, T, width), got {tuple(paths.shape)}")
    if not (isinstance(points, int) and 2 <= points <= paths.shape[1]):
        raise ValueError(f"a snippet needs 2 <= points <= {paths.shape[1]} (the path length), got {points!r}")
    pieces = paths.shape[1] // points
    # drawn by the CPU generator on every device, so a seed picks the same snippets everywhere
    start = torch.randint(0, pieces, (len(paths),), generator=generator, device="cpu").to(paths.device) * points
    index = start[:, None] + torch.arange(points, device=paths.device)
    return paths[torch.arange(len(paths), device=paths.device)[:, None], index]


def snippets_from_paths(rows, path_points: int, steps: int) -> np.ndarray:
    """Non-overlapping snippets of ``steps + 1`` consecutive states, flattened: ``rows``
    ``(paths * path_points, width)`` are paths of ``path_points`` states one after another (the
    tasks' trajectory-major layout); returns ``(paths * (path_points // (steps + 1)), (steps + 1) * width)``."""
    rows = np.asarray(rows)
    points = steps + 1
    if not (isinstance(steps, int) and 1 <= steps and points <= path_points):
        raise ValueError(f"snippet_steps must be an integer in [1, {path_points - 1}] (the paths have "
                         f"{path_points} states), got {steps!r}")
    if rows.ndim != 2 or len(rows) % path_points:
        raise ValueError(f"{len(rows)} rows are not whole paths of {path_points} states; the dataset must "
                         "list its trajectories one after another")
    paths = rows.reshape(-1, path_points, rows.shape[1])[:, :path_points // points * points]
    return np.ascontiguousarray(paths.reshape(len(paths), -1, points * rows.shape[1]).reshape(-1, points * rows.shape[1]))


class TrajectoryObjective(PathObjective):
    """Fit by rolling out over snippets of ``steps + 1`` observed states ``dt`` apart.

    The dataset's ``snippets`` and ``test_snippets`` are ``(rows, (steps + 1) * width)``
    (flattened snippets) and ``dt`` their spacing; a dataset without them gets them from its
    ``x`` and ``test_x`` paths (``prepare``: ``t_eval`` gives the states per path). A run's config
    sets ``steps`` (its ``snippet_steps`` field); ``loss`` (``'mae'``), ``method``
    (``default_method``) and ``substeps`` (1) are this object's, for ``hnn.run_experiment(config,
    dataset, TrajectoryObjective(...))``.
    """
    arrays = ("snippets", "snippets", "test_snippets", "test_snippets")

    def __init__(self, dt: float | None = None, loss: str = "mae", method: str | None = None, substeps: int = 1,
                 steps: int = RunSettings.snippet_steps, observed: str = "canonical"):
        self.dt, self.loss, self.method, self.substeps, self.steps = dt, loss, method, substeps, steps
        self.observed = observed

    def prepare(self, dataset: dict) -> dict:
        return cut_paths(dataset, ("snippets", "test_snippets"),
                         lambda rows, points: snippets_from_paths(rows, points, self.steps), "trajectory training")

    def loss_for(self, model: nn.Module, dt: float | None = None, observed: str | None = None):
        """``(x, y) -> (batch,)`` for ``hnn.train``: x, y flattened snippets (x's first state starts the rollout)
        of states in ``observed`` coordinates ``dt`` apart (default: this object's)."""
        dt = self.dt if dt is None else dt
        observed = self.observed if observed is None else observed
        if dt is None:
            raise ValueError("trajectory training needs the snippets' time step: TrajectoryObjective(dt=...) "
                             "or a dataset with 'dt'")
        width = model.input_dim

        def loss(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
            if y.shape[1] % width:
                raise ValueError(f"snippets of {y.shape[1]} columns are not whole states of width {width}")
            snippets = y.reshape(len(y), -1, width)
            return snippet_loss(model, snippets, dt, self.method, self.loss, self.substeps, start=x[:, :width],
                                observed=observed)
        return loss


