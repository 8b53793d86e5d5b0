"""What a run fits: the model kind, the dataset arrays it trains on, its loss and its final numbers.

    hnn.run_experiment(config)                                   # config.make_objective(): the kind's
    hnn.run_experiment(config, dataset, hnn.PixelObjective(("pixels", "next_pixels", "test_pixels", "test_next_pixels")))

An objective builds the untrained model that a run's args describe (its init draws from torch's
global generator, seeded by the run), gives ``hnn.train`` its options, and measures the final
train and test numbers. The run's model kind (``'hnn'``, ``'baseline'``, ``'pixel-hnn'``, ...;
``RunConfig.kind``) is saved in its ``args.json`` as ``"kind"``, and ``model_from_args`` rebuilds
a saved run's model from it through ``MODEL_KINDS``. A new model kind is one entry there
(``register_model_kind(name, objective class, build)``); a new kind of objective is an
``Objective`` subclass.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import nn

from .fixed_step import rk4_step
from .metrics import derivative_loss, mean_and_se
from .models import PixelHNN, build_model
from .structured import DissipativeHNN, SeparableHNN

DTYPES = {"float32": torch.float32, "float64": torch.float64}


class Objective:
    """The interface: subclasses implement ``final_loss`` (and ``train_options`` if they need any).

    ``arrays`` names the dataset's ``(inputs, targets, test inputs, test targets)``, each ``(rows, width)``.
    """
    arrays: tuple[str, str, str, str] = ("x", "dxdt", "test_x", "test_dxdt")

    def build(self, args: dict) -> nn.Module:
        """The untrained model of the run's ``args["kind"]`` (float32 unless ``args["dtype"]`` says otherwise)."""
        return _typed(_registered(args["kind"]).build(args), args)

    def prepare(self, dataset: dict) -> dict:
        """The dataset with the ``arrays`` this objective trains on (derived ones added); itself by default."""
        return dataset

    def train_options(self, model: nn.Module, args: dict, dataset: dict) -> dict:
        """Keyword arguments for ``hnn.train`` beyond the shared flags (``predict``, ``loss``, ...)."""
        return {}

    def final_loss(self, model: nn.Module, inputs, targets) -> tuple[float, float]:
        """The ``(mean, ±)`` train or test number saved in metrics.json."""
        raise NotImplementedError


def _typed(model: nn.Module, args: dict) -> nn.Module:
    return model.to(dtype=DTYPES[args.get("dtype", "float32")])


def check_coordinates(model: nn.Module, dataset: dict, maps_velocities: bool) -> None:
    """Raise ValueError when ``model`` cannot be fit to ``dataset``'s states: a model that reads the
    state's second half as velocities (``model.needs_velocities``) on canonical ``[q, p]``, or a
    model of canonical states (one with ``state_from_observed``) on observed ``[q, qdot]``
    (``dataset["state"] == "velocity"``) by an objective that does not map them (``maps_velocities``)."""
    velocity = dataset.get("state", "canonical") == "velocity"
    name = type(model).__name__
    if getattr(model, "needs_velocities", False) and not velocity:
        raise ValueError(f"{name} moves q by the second half of the state, a velocity, and this task's states are "
                         "canonical [q, p]; choose another --model (e.g. hnn or mechanical)")
    if velocity and hasattr(model, "state_from_observed") and not maps_velocities:
        raise ValueError(f"{name}'s field is on canonical [q, p] and this task observes [q, qdot], and it gives no "
                         "observed_time_derivative; use --objective trajectory, which maps the observed states")


class DerivativeObjective(Objective):
    """The paper's objective: fit ``time_derivative(x)`` to ``dxdt`` (an HNN, or an MLP as the baseline).

    With ``use_rk4`` the prediction is the RK4 average slope over the dataset's ``dt``; with
    ``input_noise`` each training batch's inputs get Gaussian noise.
    """

    field = None    # what final_loss measures: model.time_derivative unless train_options maps states

    def train_options(self, model: nn.Module, args: dict, dataset: dict) -> dict:
        observed = getattr(model, "observed_time_derivative", None)
        check_coordinates(model, dataset, maps_velocities=observed is not None)
        options = {"input_noise": args.get("input_noise", 0.0), "predict": None}
        if dataset.get("state") == "velocity" and observed is not None:
            # a model of canonical [q, p] fit to d/dt of observed [q, qdot] through its own mass matrix
            if args.get("use_rk4"):
                raise ValueError("--use_rk4 steps the model's own state; on observed [q, qdot] drop it")
            self.field = options["predict"] = observed
            return options
        if args.get("use_rk4"):
            if "dt" not in dataset:
                raise ValueError("--use_rk4 needs the dataset's time step; this task's get_dataset gives no 'dt'")
            dt = float(dataset["dt"])
            options["predict"] = lambda x: rk4_step(model.time_derivative, x, dt) / dt
        return options

    def final_loss(self, model: nn.Module, inputs, targets) -> tuple[float, float]:
        return derivative_loss(model, inputs, targets, field=self.field)


class PixelObjective(Objective):
    """``PixelHNN.loss``: an autoencoder whose latent moves by an HNN (or an MLP), fit on pairs of
    observations one frame apart. ``arrays`` names the dataset's (observations, the next ones,
    and their test twins), each ``(rows, input_dim)``.

    The latent noise (``input_noise``) draws from its own generator seeded ``seed + 2``;
    ``use_rk4`` steps the latent by RK4 instead of Euler.
    """
    def __init__(self, arrays: tuple[str, str, str, str] = ("x", "x_next", "test_x", "test_x_next")):
        self.arrays = tuple(arrays)

    def train_options(self, model: nn.Module, args: dict, dataset: dict) -> dict:
        noise = torch.Generator().manual_seed(args["seed"] + 2)

        def loss(x, x_next):
            return model.loss(x, x_next, input_noise=args["input_noise"], use_rk4=args["use_rk4"], generator=noise)
        return {"loss": loss}

    def final_loss(self, model: nn.Module, inputs, targets, chunk: int = 4000) -> tuple[float, float]:
        """The per-sample loss over all rows (in chunks of ``chunk``), mean ± std/sqrt(rows)."""
        param = next(model.parameters())
        x = torch.as_tensor(inputs, dtype=param.dtype, device=param.device)
        x_next = torch.as_tensor(targets, dtype=param.dtype, device=param.device)
        with torch.no_grad():
            per_sample = torch.cat([model.loss(x[i:i + chunk], x_next[i:i + chunk]) for i in range(0, len(x), chunk)])
        return mean_and_se(per_sample)


def _mlp_model(baseline: bool):
    def build(args: dict) -> nn.Module:
        return build_model(args["input_dim"], args["hidden_dim"], args["nonlinearity"], baseline, args["field_type"])
    return build


def _pixel_model(baseline: bool):
    def build(args: dict) -> nn.Module:
        return PixelHNN(args["input_dim"], args["latent_dim"], args["hidden_dim"], args["nonlinearity"], baseline,
                        args["field_type"], args.get("ae_nonlinearity", "relu"))
    return build


def _structured_model(cls):
    def build(args: dict) -> nn.Module:
        return cls(args["input_dim"], args["hidden_dim"], args["nonlinearity"])
    return build


@dataclass(frozen=True)
class ModelKind:
    """A registered model kind: the objective that trains it, ``build(args) -> nn.Module`` (its
    untrained model from a run's args; also rebuilds it on load), and what the studies read:
    ``conservative`` (it learns an H that its flow conserves, ``model.hamiltonian``),
    ``separable`` (that H is ``T(p) + V(q)``: explicit symplectic solvers apply), ``dissipative``
    (its flow loses energy on purpose, so no energy drift is measured) and its plot ``color``."""
    objective: type
    build: Callable[[dict], nn.Module]
    conservative: bool = False
    separable: bool = False
    dissipative: bool = False
    color: str = "tab:gray"


# the one place a kind is named; a run's config says which (RunConfig.kind), its args.json too
MODEL_KINDS = {
    "hnn": ModelKind(DerivativeObjective, _mlp_model(False), conservative=True, color="tab:blue"),
    "baseline": ModelKind(DerivativeObjective, _mlp_model(True), color="tab:red"),
    "separable": ModelKind(DerivativeObjective, _structured_model(SeparableHNN), conservative=True, separable=True,
                           color="tab:green"),
    "dissipative": ModelKind(DerivativeObjective, _structured_model(DissipativeHNN), dissipative=True,
                             color="tab:purple"),
    "pixel-hnn": ModelKind(PixelObjective, _pixel_model(False), conservative=True, color="tab:blue"),
    "pixel-baseline": ModelKind(PixelObjective, _pixel_model(True), color="tab:red"),
}


def register_model_kind(name: str, objective: type, build, **properties) -> None:
    """Add a model kind: runs whose config says ``model=name`` train with ``objective``, and
    ``build(args) -> nn.Module`` makes their untrained model (and rebuilds it on load);
    ``properties`` are ``ModelKind``'s (``conservative``, ``separable``, ``dissipative``, ``color``)."""
    if name in MODEL_KINDS:
        raise ValueError(f"model kind {name!r} is registered already")
    MODEL_KINDS[name] = ModelKind(objective, build, **properties)


def _registered(kind: str) -> ModelKind:
    if kind not in MODEL_KINDS:
        raise ValueError(f"unknown model kind {kind!r}; known: {sorted(MODEL_KINDS)}")
    return MODEL_KINDS[kind]


def objective_for(kind: str) -> Objective:
    """An objective that trains models of ``kind`` (its arrays are the defaults)."""
    return _registered(kind).objective()


def model_from_args(args: dict) -> nn.Module:
    """The untrained model that a run with these (saved) args trains, of the ``kind`` it recorded."""
    return objective_for(args["kind"]).build(args)
