"""The registry of model kinds and objectives: one row a kind, one row an objective.

A run's config names its kind (``RunConfig.kind``, saved in ``args.json`` as ``"kind"``) and its
objective (``RunConfig.objective``); ``model_from_args`` builds the kind's untrained model (its
init draws from torch's global generator, seeded by the run) and rebuilds a saved run's model.
What a kind *is* (its coordinates, whether it conserves an H, separable, dissipative) is declared
once, by its model class (``hnn.Model``); the row names that class, so ``--model``,
``hnn.load_run``, both studies and the peers table read the same declaration. A new kind is one
model module and one row here:

    MODEL_KINDS["toy"] = ModelKind(ToyModel, lambda args: ToyModel(args["input_dim"]), summary="...")
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import nn

from .dgnet import DiscreteGradientObjective
from .interface import Model
from .lagrangian import LagrangianNN
from .mechanical import MechanicalHNN, SecondOrderNODE
from .models import HNN, Baseline, PixelBaseline, PixelHNN, build_model
from .objectives import DerivativeObjective, PixelObjective
from .structured import DissipativeHNN, SeparableHNN
from .trajectory import TrajectoryObjective

DTYPES = {"float32": torch.float32, "float64": torch.float64}


@dataclass(frozen=True)
class ModelKind:
    """A model kind: its ``model`` class (whose declarations the studies read), ``build(args)``
    (its untrained model from a run's args; also rebuilds it on load), the ``objective`` class
    that trains it by default, its plot ``color`` and a one-line ``summary`` for ``--help`` and docs."""
    model: type
    build: Callable[[dict], nn.Module]
    objective: type = DerivativeObjective
    color: str = "tab:gray"
    summary: str = ""

    def __post_init__(self):
        if not (isinstance(self.model, type) and issubclass(self.model, Model)):
            raise TypeError(f"ModelKind.model must be an hnn.Model subclass, got {self.model!r}")

    @property
    def coordinates(self) -> str:
        """The state its field reads (``hnn.interface.COORDINATES``)."""
        return self.model.coordinates

    @property
    def conservative(self) -> bool:
        """It learns an H that its flow conserves (``model.hamiltonian``)."""
        return self.model.conservative

    @property
    def separable(self) -> bool:
        """That H is T(p) + V(q): explicit symplectic solvers apply to the learned model."""
        return self.model.separable

    @property
    def dissipative(self) -> bool:
        """Its flow loses energy on purpose (no energy drift is measured)."""
        return self.model.dissipative

    def reads(self, observed: str) -> bool:
        """Whether its model can be fit to states in ``observed`` coordinates (as they are, or mapped)."""
        return observed == self.model.coordinates or observed in self.model.takes or observed in self.model.maps


def _mlp(args: dict, baseline: bool) -> HNN:
    return build_model(args["input_dim"], args["hidden_dim"], args["nonlinearity"], baseline, args["field_type"])


def _pixel(cls) -> Callable[[dict], PixelHNN]:
    def build(args: dict) -> PixelHNN:
        return cls(args["input_dim"], args["latent_dim"], args["hidden_dim"], args["nonlinearity"],
                   field_type=args["field_type"], autoencoder_nonlinearity=args.get("ae_nonlinearity", "relu"))
    return build


def _structured(cls) -> Callable[[dict], nn.Module]:
    def build(args: dict) -> nn.Module:
        return cls(args["input_dim"], args["hidden_dim"], args["nonlinearity"])
    return build


def _second_order(cls) -> Callable[[dict], nn.Module]:
    def build(args: dict) -> nn.Module:
        return cls(args["input_dim"], args["hidden_dim"], args["nonlinearity"], periodic=args.get("periodic", False))
    return build


# the one place a kind is named; a run's config says which (RunConfig.kind), its args.json too
MODEL_KINDS: dict[str, ModelKind] = {
    "hnn": ModelKind(HNN, lambda args: _mlp(args, False), color="tab:blue",
                     summary="the paper's HNN: one MLP H(q, p), dx/dt = J grad H"),
    "baseline": ModelKind(Baseline, lambda args: _mlp(args, True), color="tab:red",
                          summary="the paper's baseline: an MLP that predicts dx/dt directly, no H"),
    "separable": ModelKind(SeparableHNN, _structured(SeparableHNN), color="tab:green",
                           summary="H = T(p) + V(q), two MLPs: leapfrog and yoshida4 are symplectic for it"),
    "dissipative": ModelKind(DissipativeHNN, _structured(DissipativeHNN), color="tab:purple",
                             summary="dx/dt = J grad H + grad D: an H and a learned dissipation (D-HNN)"),
    "mechanical": ModelKind(MechanicalHNN, _second_order(MechanicalHNN), color="tab:olive",
                            summary="H = p^T M^-1(q) p / 2 + V(q), learned mass matrix; maps observed [q, qdot]"),
    "second_order": ModelKind(SecondOrderNODE, _second_order(SecondOrderNODE), color="tab:orange",
                              summary="dq/dt = v, dv/dt = f(q, v): a second-order MLP on observed velocities, no H"),
    "lagrangian": ModelKind(LagrangianNN, _second_order(LagrangianNN), color="tab:brown",
                            summary="LNN: a black-box L(q, qdot) MLP on observed velocities, qddot by Euler-Lagrange"),
    "pixel-hnn": ModelKind(PixelHNN, _pixel(PixelHNN), PixelObjective, color="tab:blue",
                           summary="an autoencoder whose latent [q, p] moves by an HNN"),
    "pixel-baseline": ModelKind(PixelBaseline, _pixel(PixelBaseline), PixelObjective, color="tab:red",
                                summary="an autoencoder whose latent moves by an MLP"),
}

# objective name -> class: RunConfig.objective's choices
OBJECTIVES = {"derivative": DerivativeObjective, "trajectory": TrajectoryObjective,
              "discrete_gradient": DiscreteGradientObjective}


def get_kind(kind: str) -> ModelKind:
    """The row of ``kind``, or a ValueError naming the known kinds."""
    if kind not in MODEL_KINDS:
        raise ValueError(f"unknown model kind {kind!r}; known: {sorted(MODEL_KINDS)}")
    return MODEL_KINDS[kind]


def get_objective(name: str, **options):
    """A new objective called ``name`` (a key of ``OBJECTIVES``), built with ``options``."""
    if name not in OBJECTIVES:
        raise ValueError(f"unknown objective {name!r}; choose one of {sorted(OBJECTIVES)}")
    return OBJECTIVES[name](**options)


def objective_for(kind: str):
    """An objective that trains models of ``kind`` by default (its arrays are the defaults)."""
    return get_kind(kind).objective()


def model_from_args(args: dict) -> nn.Module:
    """The untrained model that a run with these (saved) args trains, of the ``kind`` it recorded
    (float32 unless ``args["dtype"]`` says otherwise)."""
    return get_kind(args["kind"]).build(args).to(dtype=DTYPES[args.get("dtype", "float32")])
