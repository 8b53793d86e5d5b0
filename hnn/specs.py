"""A run's settings, typed: what each consumer of a run reads, derived once from its config or from
a saved run's args (``run_specs``), so that no consumer reads a settings dict by string key.

    specs = hnn.specs.run_specs(config)               # an hnn.RunConfig, or the args.json of a run folder
    model = hnn.kinds.model_from_spec(specs.model)
    options = objective.train_options(model, specs.objective, dataset)
    stats = hnn.train(model, x, y, **specs.training.train_kwargs(), **options.train_kwargs())

Four frozen specs, one per consumer: ``ModelSpec`` (what a kind's builder reads), ``TrainingSpec``
(what ``hnn.train`` reads, by its keyword names), ``ObjectiveSpec`` (what an objective reads:
``Objective.train_options``) and ``FitSpec`` (what a least-squares fit reads: ``hnn.fits.solve``). A field a saved run lacks (a run saved before the field existed, or a
task without it, such as ``input_noise`` outside the 2-body and pixel tasks) takes its default, the
value that run trained with. Torch-free; a run's identity and its args.json are the config's
(``hnn.RunConfig``), untouched here.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any


def _picked(cls, values: Mapping) -> dict:
    """The entries of ``values`` that are fields of dataclass ``cls``."""
    return {f.name: values[f.name] for f in fields(cls) if f.name in values}


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
    every MLP of the model starts (``hnn.models.initialize``), applied after the kind's builder; lnn_solve:
    how the lagrangian kind solves for qddot (``hnn.names.LNN_SOLVES``); fit: how
    the weights are found (``hnn.fits.FITS``): a fit other than ``'adam'`` builds its own model
    (``hnn.fits.build``: ``hidden_dim`` sampled neurons, or the library of ``library_degree`` and
    ``library_frequencies``), float64 whatever ``dtype`` says;
    map_layers: a learned map's layers (``hnn.models.maps``); dt: the time step of the run's data (its
    dataset's ``dt``, recorded in args.json by ``hnn.policy.saved_args``), a learned map's step; bodies: the
    state's layout as bodies (``hnn.bodies.Bodies.to_dict()``, from its config's ``model_facts()``), which
    the pair kind reads.
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
    lnn_solve: str = "solve"
    fit: str = "adam"
    library_degree: int = 3
    library_frequencies: int = 1
    map_layers: int = 4
    dt: float | None = None
    bodies: dict | None = None

    @classmethod
    def from_args(cls, args: Mapping) -> ModelSpec:
        """The spec of a run's (saved) args: its declared fields, the defaults for any it lacks."""
        if "kind" not in args:
            raise ValueError(f"a run's args need its model's kind to build it; got keys {sorted(args)}")
        values = _picked(cls, args)
        # the measured task's --periodic names the angle columns: a model reads all of its q as angles or none
        if "periodic" in values:
            values["periodic"] = bool(values["periodic"])
        return cls(**values)


@dataclass(frozen=True)
class TrainingSpec:
    """What ``hnn.train`` reads of a run: its keyword arguments of the same names (their defaults are
    ``hnn.train``'s). The loop's own options (``predict``, ``loss``, ``input_noise``, ...) are the
    objective's (``Objective.train_options``)."""
    total_steps: int = 2000
    learn_rate: float = 1e-3
    weight_decay: float = 1e-4
    batch_size: int | None = None
    seed: int = 0
    print_every: int = 200
    verbose: bool = False
    optimizer: str = "adam"
    schedule: str = "constant"
    clip_grad: float = 0.0

    @classmethod
    def from_args(cls, args: Mapping) -> TrainingSpec:
        """The spec of a run's (saved) args: its fields, the defaults for any it lacks."""
        return cls(**_picked(cls, args))

    def train_kwargs(self) -> dict[str, Any]:
        """``hnn.train``'s keyword arguments (and ``hnn.trainers.vmap.train_vmap``'s of the same names)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class ObjectiveSpec:
    """What an objective reads of a run (``Objective.train_options``): ``seed`` (the pixel objective's
    noise generator starts at seed + 2), ``input_noise`` (std of the Gaussian noise on each training
    batch's inputs, or on the pixel latent), ``use_rk4`` (fit the RK4 average slope over the data's dt),
    ``derivative_loss`` (``hnn.names.DERIVATIVE_LOSSES``), ``balance`` (``hnn.names.BALANCES``; a run
    saved before the field existed trained unbalanced: ``'off'``) and ``units`` (``hnn.names.UNITS``: the
    coordinates the fit runs in, ``hnn.units``; ``'off'`` before the field existed)."""
    seed: int = 0
    input_noise: float = 0.0
    use_rk4: bool = False
    derivative_loss: str = "l2"
    balance: str = "off"
    units: str = "off"

    @classmethod
    def from_args(cls, args: Mapping) -> ObjectiveSpec:
        """The spec of a run's (saved) args: its fields, the defaults for any it lacks."""
        return cls(**_picked(cls, args))


@dataclass(frozen=True)
class FitSpec:
    """What a least-squares fit reads of a run (``hnn.fits.solve``'s keywords): ``fit`` (``hnn.names.FITS``; a run
    saved before the field existed trained by ``'adam'``), ``seed`` (draws the sampled neurons), ``fit_rcond``
    (the ridge relative to unit columns, or ``'auto'``) and ``library_threshold`` (a library's smallest coefficient kept)."""
    fit: str = "adam"
    seed: int = 0
    fit_rcond: float | str = "auto"
    library_threshold: float = 0.05

    @classmethod
    def from_args(cls, args: Mapping) -> FitSpec:
        """The spec of a run's (saved) args: its fields, the defaults for any it lacks."""
        return cls(**_picked(cls, args))

    def solve_kwargs(self) -> dict[str, Any]:
        """``hnn.fits.solve``'s keyword arguments."""
        return {"fit": self.fit, "seed": self.seed, "rcond": self.fit_rcond, "threshold": self.library_threshold}


@dataclass(frozen=True)
class RunSpecs:
    """A run's typed specs: ``model``, ``training``, ``objective``, ``fit``."""
    model: ModelSpec
    training: TrainingSpec
    objective: ObjectiveSpec
    fit: FitSpec = FitSpec()


def run_specs(source) -> RunSpecs:
    """The typed specs of a run: ``source`` is its config (an ``hnn.RunConfig``: its fields, model facts
    and kind) or a saved run's args (``args.json``, as ``hnn.load_run`` returns them)."""
    if isinstance(source, Mapping):
        values = source
    elif dataclasses.is_dataclass(source) and hasattr(source, "to_dict"):
        values = {**source.to_dict(), "kind": source.kind}
    else:
        raise TypeError(f"run_specs reads an hnn.RunConfig or a run's saved args (a dict), got {type(source).__name__}")
    return RunSpecs(ModelSpec.from_args(values), TrainingSpec.from_args(values), ObjectiveSpec.from_args(values),
                    FitSpec.from_args(values))
