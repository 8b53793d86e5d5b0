"""Hamiltonian Neural Networks (Greydanus, Dzamba & Yosinski, 2019): models, integrators,
the training loop, the paper's metrics, and saved runs.

    import hnn
    model = hnn.HNN(2, hnn.MLP(2, 200, 2))
    stats = hnn.train(model, x, dxdt)
    traj = hnn.rollout(model.time_derivative, x0, t_eval)   # (batch, time, 2)
"""
from .errors import ConvergenceError, DivergenceError
from .integrate import rollout
from .fixed_step import YOSHIDA_WEIGHTS, rk4_step
from .solvers import SOLVERS, SYMPLECTIC_METHODS, Solver, get_solver, register_solver
from .metrics import batch_means_se, derivative_loss, energy_mse, mean_and_se
from .interface import COORDINATES, Model
from .models import HNN, MLP, Baseline, MLPAutoencoder, PixelHNN, build_model, get_nonlinearity, permutation_tensor
from .structured import DissipativeHNN, SeparableHNN
from .objectives import DerivativeObjective, Objective, PixelObjective
from .mechanical import MechanicalHNN, SecondOrderNODE
from .lagrangian import LagrangianNN, SingularLagrangianError
from .trajectory import TrajectoryObjective, snippet_loss
from .dgnet import DiscreteGradientObjective
from .kinds import MODEL_KINDS, OBJECTIVES, ModelKind, get_objective
from .config import RunConfig
from .runs import find_run, load_run, run_dir, run_experiment, save_run
from .tasks import TaskSpec, available_tasks, load_task, task_spec
from .training import train
from .gifs import write_gif
from . import cli, discrete_gradient, grouped, interface, kinds, nbody, objectives, paper, trajectory
from .evaluation import PROTOCOLS, EnergyProtocol, energy_bump, evaluate_energy, get_protocol

__all__ = [
    "Model", "COORDINATES", "Baseline", "HNN", "MLP", "MLPAutoencoder", "PixelHNN", "build_model", "get_nonlinearity", "permutation_tensor",
    "rollout", "rk4_step", "DivergenceError", "ConvergenceError", "SYMPLECTIC_METHODS", "YOSHIDA_WEIGHTS",
    "SOLVERS", "Solver", "get_solver", "register_solver",
    "train",
    "derivative_loss", "mean_and_se", "batch_means_se", "energy_mse",
    "RunConfig", "run_experiment", "run_dir", "save_run", "load_run", "find_run",
    "SeparableHNN", "DissipativeHNN", "MechanicalHNN", "SecondOrderNODE", "LagrangianNN", "SingularLagrangianError",
    "TrajectoryObjective", "DiscreteGradientObjective", "OBJECTIVES", "get_objective", "snippet_loss", "trajectory",
    "Objective", "DerivativeObjective", "PixelObjective", "MODEL_KINDS", "ModelKind",
    "load_task", "available_tasks", "task_spec", "TaskSpec", "write_gif",
    "EnergyProtocol", "PROTOCOLS", "get_protocol", "evaluate_energy", "energy_bump", "cli", "discrete_gradient", "grouped", "interface", "kinds", "nbody", "objectives",
    "paper",
]
