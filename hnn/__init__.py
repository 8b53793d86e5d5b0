"""Hamiltonian Neural Networks (Greydanus, Dzamba & Yosinski, 2019): models, integrators,
the training loop, the paper's metrics, and saved runs.

    import hnn
    model = hnn.HNN(2, hnn.MLP(2, 200, 2))
    stats = hnn.train(model, x, dxdt)
    model, stats = hnn.fit_least_squares("hnn", x, dxdt, fit="swim", width=1000)   # one solve, seconds
    traj = hnn.rollout(model.time_derivative, x0, t_eval)   # (batch, time, 2)

``hnn`` itself gives the 42 names of ``__all__``; the rest is reached through its room or module
(``hnn.models.ConstraintGraph``, ``hnn.integrators.rk4_step``, ``hnn.runs.find_run``).
``import hnn`` itself loads no torch, so that a ``train.py``'s ``--help`` and flag errors answer
at once: the light modules (``_LIGHT``: ``cli``, ``command``, ``config``, ``tasks``, ``io``, ...) and
``RunConfig`` and ``TaskSpec`` (``_LIGHT_NAMES``: a task's ``task.py`` reads it) load on use, and the first
use of any other name loads the whole package.

The modules stand in layers (``_LAYERS``; ``tests/test_layers.py`` reads every import against it):
a module imports its own layer and those below, never one above, and the two middle rooms know
nothing of each other.

- base: errors, the model interface, modes a caller sets for a lower layer, names, a run's settings (each
  declared once: ``hnn.settings``) and their specs, io, metrics, the dataset cache, the GIF writer, a block's
  torch thread count, progress lines;
- two rooms of one level, each a folder: ``hnn.integrators`` (fields in, paths out: no network) |
  ``hnn.models`` (networks and their fields: no solver, no objective);
- training: the objectives (``hnn.objectives``, a folder: the derivative fit, trajectory snippets,
  DGNet's pairs, a map's step), the kinds registry, ``hnn.train``, the ways of finding a run's weights
  (``hnn.trainers``, a folder: the lone loop, the group loop, its closed-form and vmap groups, the
  least-squares solve's entry), evaluation, datasets, and the least-squares fits (``hnn.fits``, a folder:
  ``hnn.fit_least_squares``);
- runs: config, cli, a ``train.py``'s command, a run's policy settled once (``hnn.prepare``), run folders,
  task discovery;
- orbits: the orbit tasks' physics and config (``hnn.orbits``, a folder: the gravity of n bodies, the
  close-encounter thresholds, the 2- and 3-body tasks' ``OrbitConfig``);
- sweeps: many runs at once (``hnn.sweeps``, a folder: the sweep, where it trains, its flags, group
  runs, stopping). A library reader can skip it and ``orbits``.

A folder loads its modules on first use (``hnn.sweeps.sweep``), so its light ones (``hnn.sweeps.flags``,
``hnn.orbits.config``) answer ``--help`` without torch.
"""
import importlib
import pkgutil
from typing import TYPE_CHECKING

_LIGHT = ("cli", "command", "config", "settings", "names", "kind_docs", "io", "errors", "modes", "progress", "tasks", "orbits",
          "sweeps", "bodies")
_LIGHT_NAMES = {"RunConfig": "config", "TaskSpec": "tasks"}     # name -> its light module

# layer -> its modules and folders (every module in a folder has the folder's layer); a module may import
# from its own layer and the ones before it, except that the two rooms of one level, "integrators" and
# "models", may not import each other
_LAYERS = {
    "base": ("errors", "names", "settings", "io", "interface", "modes", "kind_docs", "metrics", "specs", "cache",
             "gifs", "threads", "progress", "bodies", "cells"),
    "integrators": ("integrators",),
    "models": ("models",),
    "training": ("balance", "units", "training", "trainers", "objectives", "kinds", "evaluation", "datasets",
                 "fits"),
    "runs": ("config", "cli", "command", "policy", "runs", "tasks"),
    "orbits": ("orbits",),
    "sweeps": ("sweeps",),
}

# the public face: module -> the names it gives ``hnn``, in the order they load (everything else is
# reached through its room or module: ``hnn.models.ConstraintGraph``, ``hnn.runs.find_run``)
_PUBLIC = {
    "errors": ("BudgetError", "ConvergenceError", "DivergenceError"),
    "interface": ("Model",),
    "integrators": ("SOLVERS", "Solver", "get_solver", "register_solver", "rollout"),
    "models": ("HNN", "MLP", "PixelHNN", "SeparableHNN", "DissipativeHNN", "MechanicalHNN", "ConstrainedHNN",
               "build_model"),
    "metrics": ("derivative_mse", "energy_mse"),
    "objectives": ("DerivativeObjective", "LoopOptions", "Objective"),
    "kinds": ("MODEL_KINDS", "OBJECTIVES"),
    "training": ("train",),
    "fits": ("FITS", "fit_least_squares"),
    "evaluation": ("EnergyProtocol", "evaluate_energy"),
    "config": ("RunConfig",),
    "policy": ("Prepared", "prepare"),
    "runs": ("load_run", "run_experiment"),
    "tasks": ("PROTOCOLS", "TaskData", "TaskSpec", "available_tasks", "load_task", "task_spec"),
}
_ROOMS = ("integrators", "models")

if TYPE_CHECKING:     # the public names spelled out for type checkers and editors (tests/test_layers.py
    # holds them equal to _PUBLIC); at run time __getattr__ binds them on first use, so --help loads no torch
    from .errors import BudgetError, ConvergenceError, DivergenceError  # noqa: F401
    from .interface import Model  # noqa: F401
    from .integrators import SOLVERS, Solver, get_solver, register_solver, rollout  # noqa: F401
    from .models import (HNN, MLP, PixelHNN, SeparableHNN, DissipativeHNN, MechanicalHNN,  # noqa: F401
                         ConstrainedHNN, build_model)
    from .metrics import derivative_mse, energy_mse  # noqa: F401
    from .objectives import DerivativeObjective, LoopOptions, Objective  # noqa: F401
    from .kinds import MODEL_KINDS, OBJECTIVES  # noqa: F401
    from .training import train  # noqa: F401
    from .fits import FITS, fit_least_squares  # noqa: F401
    from .evaluation import EnergyProtocol, evaluate_energy  # noqa: F401
    from .config import RunConfig  # noqa: F401
    from .policy import Prepared, prepare  # noqa: F401
    from .runs import load_run, run_experiment  # noqa: F401
    from .tasks import PROTOCOLS, TaskData, TaskSpec, available_tasks, load_task, task_spec  # noqa: F401
    from . import integrators, models  # noqa: F401


def _load_all() -> None:
    """Import every module of every layer, a folder's too, and bind the public names (this is where torch
    and scipy load; every built-in model kind is registered after it, and ``hnn.<module>`` is bound for each)."""
    for modules in _LAYERS.values():
        for module in modules:
            loaded = importlib.import_module(f"{__name__}.{module}")
            for inner in pkgutil.iter_modules(getattr(loaded, "__path__", ())):
                importlib.import_module(f"{loaded.__name__}.{inner.name}")
    for module, names in _PUBLIC.items():
        loaded = importlib.import_module(f"{__name__}.{module}")
        globals().update({name: getattr(loaded, name) for name in names})


def __getattr__(name: str):
    """A light module or a light name alone; any other name loads the whole package first."""
    if name in _LIGHT:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _LIGHT_NAMES:
        return getattr(importlib.import_module(f"{__name__}.{_LIGHT_NAMES[name]}"), name)
    if name.startswith("__"):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    _load_all()
    if name not in globals():
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return globals()[name]


def __dir__():
    # tab completion lists the public names without loading torch
    return sorted(set(globals()) | set(__all__) | set(_LIGHT))


__all__ = [name for names in _PUBLIC.values() for name in names] + list(_ROOMS)
