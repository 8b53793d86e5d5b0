"""Hamiltonian Neural Networks (Greydanus, Dzamba & Yosinski, 2019): models, integrators,
the training loop, the paper's metrics, and saved runs.

    import hnn
    model = hnn.HNN(2, hnn.MLP(2, 200, 2))
    stats = hnn.train(model, x, dxdt)
    traj = hnn.rollout(model.time_derivative, x0, t_eval)   # (batch, time, 2)

``import hnn`` itself loads no torch, so that a ``train.py``'s ``--help`` and flag errors answer
at once: the light modules (``cli``, ``config``, ``names``, ``kind_docs``, ``io``, ``errors``)
and ``RunConfig`` load on use, and the first use of any other name loads the whole package.

The modules stand in layers (``_LAYERS``; ``tests/test_layers.py`` reads every import against it):
a module imports its own layer and those below, never one above, and the two middle rooms know
nothing of each other.

- base: errors, the model interface, modes a caller sets for a lower layer, names, io, metrics;
- integrators (fields in, paths out: no network) | models (networks and their fields: no solver,
  no objective);
- training: objectives, the kinds registry, the loop, grouped training, evaluation, datasets;
- runs: config, cli, run folders, task discovery, the tasks' shared systems.
"""
import importlib

_LIGHT = ("cli", "config", "names", "kind_docs", "io", "errors", "orbit_config", "modes")

# layer -> its modules; a module may import from its own layer and the ones before it, except that
# "integrators" and "models" (one level) may not import each other
_LAYERS = {
    "base": ("errors", "names", "io", "interface", "modes", "kind_docs", "metrics", "dop853"),
    "integrators": ("fixed_step", "adaptive", "solvers", "discrete_gradient", "integrate"),
    "models": ("tanh_mlp", "models", "structured", "mechanical", "constrained", "lagrangian"),
    "training": ("objectives", "trajectory", "dgnet", "training", "grouped", "kinds", "evaluation", "datasets"),
    "runs": ("config", "cli", "runs", "tasks", "cache", "gifs", "orbit_config", "nbody", "paper", "group_runs"),
}

# module -> the public names it gives the package, in the order they load
_PUBLIC = {
    "errors": ("ConvergenceError", "DivergenceError"),
    "integrate": ("rollout",),
    "fixed_step": ("YOSHIDA_WEIGHTS", "rk4_step"),
    "solvers": ("SOLVERS", "SYMPLECTIC_METHODS", "Solver", "get_solver", "register_solver"),
    "metrics": ("batch_means_se", "derivative_loss", "energy_mse", "mean_and_se"),
    "interface": ("COORDINATES", "Model"),
    "models": ("HNN", "MLP", "Baseline", "MLPAutoencoder", "PixelHNN", "build_model", "get_nonlinearity",
               "permutation_tensor"),
    "structured": ("DissipativeHNN", "SeparableHNN"),
    "objectives": ("DerivativeObjective", "Objective", "PixelObjective"),
    "config": ("RunConfig",),
    "mechanical": ("MechanicalHNN", "SecondOrderNODE"),
    "constrained": ("ConstrainedHNN", "ConstrainedLNN", "ConstraintGraph"),
    "lagrangian": ("LagrangianNN", "SingularLagrangianError"),
    "dgnet": ("DiscreteGradientObjective",),
    "discrete_gradient": (),
    "trajectory": ("TrajectoryObjective", "snippet_loss"),
    "kinds": ("MODEL_KINDS", "OBJECTIVES", "ModelKind", "get_objective"),
    "runs": ("find_run", "load_run", "run_dir", "run_experiment", "save_run"),
    "tasks": ("PROTOCOLS", "TaskSpec", "available_tasks", "get_protocol", "load_task", "task_spec"),
    "training": ("train",),
    "gifs": ("write_gif",),
    "evaluation": ("EnergyProtocol", "energy_bump", "evaluate_energy"),
    "cli": (), "grouped": (), "group_runs": (), "modes": (), "nbody": (), "paper": (), "kind_docs": (),
}


def _load_all() -> None:
    """Import every module of ``_PUBLIC`` and bind its names (this is where torch and scipy load;
    every built-in model kind is registered after it)."""
    for module, names in _PUBLIC.items():
        loaded = importlib.import_module(f"{__name__}.{module}")
        globals().update({name: getattr(loaded, name) for name in names})


def __getattr__(name: str):
    """A light module or ``RunConfig`` alone; any other name loads the whole package first."""
    if name in _LIGHT:
        return importlib.import_module(f"{__name__}.{name}")
    if name == "RunConfig":
        return importlib.import_module(f"{__name__}.config").RunConfig
    if name.startswith("__"):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    _load_all()
    if name not in globals():
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return globals()[name]


def __dir__():
    _load_all()
    return sorted(globals())


__all__ = [
    "Model", "COORDINATES", "Baseline", "HNN", "MLP", "MLPAutoencoder", "PixelHNN", "build_model", "get_nonlinearity", "permutation_tensor",
    "rollout", "rk4_step", "DivergenceError", "ConvergenceError", "SYMPLECTIC_METHODS", "YOSHIDA_WEIGHTS",
    "SOLVERS", "Solver", "get_solver", "register_solver",
    "train",
    "derivative_loss", "mean_and_se", "batch_means_se", "energy_mse",
    "RunConfig", "run_experiment", "run_dir", "save_run", "load_run", "find_run",
    "SeparableHNN", "DissipativeHNN", "MechanicalHNN", "SecondOrderNODE",
    "ConstrainedHNN", "ConstrainedLNN", "ConstraintGraph", "LagrangianNN", "SingularLagrangianError",
    "DiscreteGradientObjective",
    "TrajectoryObjective", "OBJECTIVES", "get_objective", "snippet_loss", "trajectory",
    "Objective", "DerivativeObjective", "PixelObjective", "MODEL_KINDS", "ModelKind",
    "load_task", "available_tasks", "task_spec", "TaskSpec", "write_gif",
    "EnergyProtocol", "PROTOCOLS", "get_protocol", "evaluate_energy", "energy_bump", "cli", "constrained", "discrete_gradient", "grouped", "group_runs", "interface", "modes", "kinds", "nbody",
    "objectives", "paper", "kind_docs",
]
