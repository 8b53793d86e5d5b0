"""The registry of model kinds and objectives: one row a kind, one row an objective.

A run's config names its kind (``RunConfig.kind``, saved in ``args.json`` as ``"kind"``) and its
objective (``RunConfig.objective``); ``model_from_args`` reads a run's args into a ``ModelSpec``
(the declared fields a builder may read) and builds the kind's untrained model from it (its init
draws from torch's global generator, seeded by the run), which also rebuilds a saved run's model.
What a kind *is* (its coordinates, whether it conserves an H, separable, dissipative) is declared
once, by its model class (``hnn.Model``); the row names that class, so ``--model``,
``hnn.load_run``, both studies and the peers table read the same declaration. A new kind is one
model module and one row here:

    MODEL_KINDS["toy"] = ModelKind(ToyModel, lambda spec: ToyModel(spec.input_dim))     # and its prose in hnn/kind_docs.py
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import torch
from torch import nn

from .models.constrained import ConstrainedHNN, ConstrainedLNN, ConstraintGraph
from .dgnet import DiscreteGradientObjective
from .interface import Model
from .models.lagrangian import LagrangianNN
from .models.mechanical import MechanicalHNN, SecondOrderNODE
from .models.mlp import initialize
from .models.hamiltonian import Baseline, HNN, build_model
from .models.pixel import PixelBaseline, PixelHNN
from .objectives import DerivativeObjective, PixelObjective
from .models.structured import DissipativeHNN, SeparableHNN
from .trajectory import TrajectoryObjective
from .units import wrap_saved

DTYPES = {"float32": torch.float32, "float64": torch.float64}


@dataclass(frozen=True)
class ModelSpec:
    """What a kind's builder reads of a run, declared (a run's ``args.json`` holds these among the
    rest of its config; ``from_args`` picks them out).

    kind: a key of ``MODEL_KINDS``; input_dim: the state's width 2n (pixels: the frame's pixels; the
    constrained kinds read theirs from the graph);
    hidden_dim, nonlinearity: the MLPs'; field_type: what the paper's HNN learns (solenoidal,
    conservative, both); latent_dim, ae_nonlinearity: the pixel autoencoder's; periodic: positions
    are angles (the second-order kinds read cos q, sin q); constraints: the task's constraint graph
    (``ConstraintGraph.to_dict()``, the constrained kinds); dtype: float32 or float64; init: how
    every MLP of the model starts (``hnn.models.initialize``), applied after the kind's builder.
    """
    kind: str
    input_dim: int | None = None
    hidden_dim: int = 200
    nonlinearity: str = "tanh"
    field_type: str = "solenoidal"
    latent_dim: int = 2
    ae_nonlinearity: str = "relu"
    periodic: bool = False
    constraints: dict | None = None
    dtype: str = "float32"
    init: str = "orthogonal"

    @classmethod
    def from_args(cls, args: dict) -> ModelSpec:
        """The spec of a run's (saved) args: its declared fields, the defaults for any it lacks."""
        if "kind" not in args:
            raise ValueError(f"a run's args need its model's kind to build it; got keys {sorted(args)}")
        values = {f.name: args[f.name] for f in fields(cls) if f.name in args}
        # the measured task's --periodic names the angle columns: a model reads all of its q as angles or none
        if "periodic" in values:
            values["periodic"] = bool(values["periodic"])
        return cls(**values)


@dataclass(frozen=True)
class ModelKind:
    """A model kind: its ``model`` class (whose declarations the studies read), ``build(spec)``
    (its untrained model from a run's ``ModelSpec``; also rebuilds it on load), the ``objective`` class
    that trains it by default, its plot ``color`` and ``studied``: whether the studies (scene, measured,
    peers) train it by default (False for a kind whose rollouts are not yet affordable there). Its prose for readers (``--help``, the README,
    docs/python.md) is ``hnn.kind_docs.KIND_DOCS[kind]``, torch-free so ``--help`` answers at once."""
    model: type
    build: Callable[[ModelSpec], nn.Module]
    objective: type = DerivativeObjective
    color: str = "tab:gray"
    studied: bool = True

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


def _mlp(spec: ModelSpec, baseline: bool) -> HNN:
    return build_model(spec.input_dim, spec.hidden_dim, spec.nonlinearity, baseline, spec.field_type)


def _pixel(cls) -> Callable[[ModelSpec], PixelHNN]:
    def build(spec: ModelSpec) -> PixelHNN:
        return cls(spec.input_dim, spec.latent_dim, spec.hidden_dim, spec.nonlinearity,
                   field_type=spec.field_type, autoencoder_nonlinearity=spec.ae_nonlinearity)
    return build


def _structured(cls) -> Callable[[ModelSpec], nn.Module]:
    def build(spec: ModelSpec) -> nn.Module:
        return cls(spec.input_dim, spec.hidden_dim, spec.nonlinearity)
    return build


def _second_order(cls) -> Callable[[ModelSpec], nn.Module]:
    def build(spec: ModelSpec) -> nn.Module:
        return cls(spec.input_dim, spec.hidden_dim, spec.nonlinearity, periodic=spec.periodic)
    return build


def _constrained(cls) -> Callable[[ModelSpec], nn.Module]:
    def build(spec: ModelSpec) -> nn.Module:
        if spec.constraints is None:
            raise ValueError(f"the {spec.kind} kind needs the task's constraint graph (ModelSpec.constraints, "
                             "from its config's model_facts()); this task declares none: train it on the chain task "
                             "(experiment-chain) or give the task's Config a model_facts() with 'constraints'")
        return cls(ConstraintGraph.from_dict(spec.constraints), spec.hidden_dim, spec.nonlinearity)
    return build


# the one place a kind is named; a run's config says which (RunConfig.kind), its args.json too
MODEL_KINDS: dict[str, ModelKind] = {
    "hnn": ModelKind(HNN, lambda spec: _mlp(spec, False), color="tab:blue"),
    "baseline": ModelKind(Baseline, lambda spec: _mlp(spec, True), color="tab:red"),
    "separable": ModelKind(SeparableHNN, _structured(SeparableHNN), color="tab:green"),
    "dissipative": ModelKind(DissipativeHNN, _structured(DissipativeHNN), color="tab:purple"),
    "mechanical": ModelKind(MechanicalHNN, _second_order(MechanicalHNN), color="tab:olive"),
    "second_order": ModelKind(SecondOrderNODE, _second_order(SecondOrderNODE), color="tab:orange"),
    "constrained": ModelKind(ConstrainedHNN, _constrained(ConstrainedHNN), color="tab:cyan"),
    "constrained_lagrangian": ModelKind(ConstrainedLNN, _constrained(ConstrainedLNN), color="tab:pink"),
    # not in the scene studies: a barely trained black-box L's flow is stiff (one dopri5 rollout of it took
    # minutes in the measured study); the peers' tables train it with the LNN's own activation and give its
    # rollouts an iteration budget (analysis/chains/peers.py)
    "lagrangian": ModelKind(LagrangianNN, _second_order(LagrangianNN), color="tab:brown", studied=False),
    "pixel-hnn": ModelKind(PixelHNN, _pixel(PixelHNN), PixelObjective, color="tab:blue"),
    "pixel-baseline": ModelKind(PixelBaseline, _pixel(PixelBaseline), PixelObjective, color="tab:red"),
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


def model_from_args(args: dict, device: torch.device | str = "cpu") -> nn.Module:
    """The untrained model that a run with these (saved) args trains, of the ``kind`` it recorded
    (float32 unless its ``dtype`` says otherwise): its ``ModelSpec`` built by the kind's row, on ``device``.

    The weights are drawn on the CPU whatever torch's default device, then moved: one seed gives the
    same initial model on every device (a GPU's generator draws other numbers)."""
    spec = ModelSpec.from_args(args)
    with torch.device("cpu"):
        model = wrap_saved(initialize(get_kind(spec.kind).build(spec), spec.init), args)   # in user units (hnn.units)
    return model.to(dtype=DTYPES[spec.dtype], device=device)
