"""A run is a config: ``RunConfig`` holds every field of a training run, with the original's names.

    config = SpringConfig(total_steps=10, hidden_dim=16)     # a task's subclass (experiment-spring/train.py)
    folder = hnn.run_experiment(config)                     # trains, saves, returns the run folder

A task subclasses ``RunConfig``: it sets its defaults (``name``, ``input_dim``, ``weight_decay``,
...), adds its own fields (declared with ``setting``, which gives each its ``--help`` text and
how its flag parses), and implements ``dataset()``. ``hnn.cli.parse(SpringConfig, argv)`` builds
the command line from the fields, so every field is a flag with the field's spelling and default.

A config's identity is every field but the display-only ones (``display_only=True``: what is
printed or how fast, never what is trained) and ``save_dir`` (where it is saved): its short hash
names the run folder ``<name>-<model>-seed<seed>-<hash>``, so two configs never share a folder
and a copied output folder is found again where it lies.
"""
from __future__ import annotations

import dataclasses
import hashlib
import inspect
import json
from dataclasses import dataclass
from typing import Any, ClassVar

from . import cli
from .names import (ACTIVATION, BALANCES, DERIVATIVE_LOSSES, DTYPES, FIELD_TYPES, FITS, HIDDEN_DIM, INITS, LNN_SOLVES,
                    MAP_LAYERS, NONLINEARITIES, OBJECTIVES, OPTIMIZERS, SCHEDULES, UNITS)


_ANY = object()      # a setting's identity_value when the identity holds the field's own value


def setting(default: Any, help: str, *, parse=None, choices=None, display_only: bool = False,
            identity_at_default: bool = True, identity_value: Any = _ANY) -> Any:
    """A config field with its flag's ``help`` text; ``parse(text) -> value`` (an argparse
    ``type``, default: the type of ``default``), ``choices`` and ``display_only`` as in argparse.
    ``identity_at_default=False``: a field added after runs were saved, which enters a run's identity
    only when set away from its default, so every run saved before it keeps its folder and is reused.
    ``identity_value``: a field that changes where a run trains, not what it trains (the device),
    which the identity records as this value whatever it holds: a run is the same run on every device,
    and the keys saved while the field was part of the identity stay valid."""
    return dataclasses.field(default=default, metadata={"help": help, "parse": parse, "choices": choices,
                                                        "display_only": display_only,
                                                        "identity_at_default": identity_at_default,
                                                        "identity_value": identity_value})


@dataclass
class RunConfig:
    """One training run: the original's flags with its defaults, plus the knobs it hard-coded."""
    input_dim: int = setting(2, "width of the state x = [q, p] (fixed by the task)")
    hidden_dim: int = setting(HIDDEN_DIM, "hidden units per layer of the MLP (of the sampled layer with --fit swim or elm)",
                              parse=cli.int_at_least(1))
    learn_rate: float = setting(1e-3, "Adam learning rate", parse=cli.positive_float)
    weight_decay: float = setting(1e-4, "Adam weight decay (hard-coded per task in the original)",
                                  parse=cli.nonnegative_float)
    optimizer: str = setting("adam", "adam (weight decay added to the gradient, the paper's) or adamw (decoupled "
                                     "weight decay, CHNN's)", choices=OPTIMIZERS)
    schedule: str = setting("constant", "learning rate over the run: constant (the paper's) or cosine (annealed "
                                        "to 0 at the last step, CHNN's)", choices=SCHEDULES)
    clip_grad: float = setting(0.0, "clip each step's gradient to this global norm (0: never); for runs whose "
                                    "loss spikes, such as rollouts through long snippets", parse=cli.nonnegative_float)
    batch_size: int | None = setting(None, "minibatch size; none/0/full = full batch", parse=cli.optional_int)
    train_fraction: float = setting(1.0, "train on this fraction of the training rows, drawn once from the seed "
                                         "(the test set stays whole); for studies of how much data a model needs",
                                    parse=cli.fraction)
    nonlinearity: str = setting(ACTIVATION, "activation of the MLP", choices=NONLINEARITIES)
    init: str = setting("orthogonal", "how the MLPs' weights start: orthogonal (the paper's: orthogonal weights, "
                                      "torch's default biases), zero_bias (DGNet's: orthogonal weights, zero biases), "
                                      "lnn (the LNN's: scaled normal weights, zero biases) or lnn_convex (the LNN's with nonnegative weights after "
                                      "the first layer: with softplus, L convex in qdot at step 0, so its first steps "
                                      "train)", choices=INITS,
                        identity_at_default=False)
    lnn_solve: str = setting("solve", "how the lagrangian kind solves d2L/dqdot2 qddot = ... for qddot: solve (stops with "
                                      "an error naming the states where d2L/dqdot2 is singular) or pinv (the LNN authors' "
                                      "pseudo-inverse there, which trains on through them); read by that kind only",
                             choices=LNN_SOLVES, identity_at_default=False)
    total_steps: int = setting(2000, "optimizer steps; the loop runs total_steps + 1, as the original",
                               parse=cli.int_at_least(0))
    print_every: int = setting(200, "print (and test) every N steps; changes what is printed and the test loss's "
                                    "sampling in metrics.json, never what is trained", parse=cli.int_at_least(1),
                               display_only=True)
    name: str = setting("run", "run name, the prefix of the run folder")
    model: str = setting("hnn", "model kind (a row of hnn.MODEL_KINDS describes each)")
    use_rk4: bool = setting(False, "fit the RK4 average slope of the learned field over one data time step dt, "
                                   "(x(t+dt) - x(t))/dt of one RK4 step, to the true dx/dt (the original crashed on "
                                   "this flag); default: fit dx/dt itself")
    objective: str = setting("derivative", "what the model is fit to: derivative (dx/dt at every state, the paper's) "
                                           "or trajectory (its rollout over snippets of snippet_steps + 1 observed "
                                           "states, through RK4, or leapfrog for a separable model; what measured "
                                           "paths without derivatives allow) or discrete_gradient (DGNet's: "
                                           "(x_{n+1} - x_n)/dt by the discrete gradient of the learned H between "
                                           "the two states; conservative kinds, tasks with paths) or map (a learned "
                                           "map's one step fit to the next observed state: the map kinds' own, "
                                           "which derivative, the default, gives them too)",
                             choices=OBJECTIVES)
    derivative_loss: str = setting("l2", "the error of a fit of dx/dt (--objective derivative): l2, squared (the "
                                         "paper's), or l1, absolute (the LNN's)", choices=DERIVATIVE_LOSSES,
                                   identity_at_default=False)
    balance: str = setting("auto", "weigh each component of dx/dt in the fit's loss by its RMS over the training "
                                   "targets, so no unit decides what is learned (--objective derivative): rms (always), "
                                   "off (the paper's plain loss) or auto (rms where the largest component's RMS exceeds "
                                   "the smallest's over 10x: hnn.balance)", choices=BALANCES, identity_at_default=False)
    # the default moved from off to auto, which trains every task's default data as off did (hnn.units,
    # AUTO_FAR): identity_at_default=False keeps each saved run's key, and off now names its own
    units: str = setting("auto", "train in the canonical units of the data (q / s_q, p / s_p, t / s_t, the RMS sizes of the "
                                 "training data, so Hamilton's equations keep their form) and save a model that answers in "
                                 "the data's units: auto (where the RMS of q or p lies outside [0.1, 10] or that of a "
                                 "rate outside [0.01, 100]: hnn.units), on (always) or off (the data's units)", choices=UNITS,
                         identity_at_default=False)
    fit: str = setting("adam", "how the weights are found: adam (the training loop, the paper's) or one least-squares "
                               "solve of dx/dt in float64 (hnn.fits; the hnn, separable, baseline and pairwise kinds, the "
                               "last over radial features of the pairs' distances): swim (a "
                               "hidden layer of --hidden_dim tanh neurons drawn from pairs of training states, Rahma, "
                               "Datar & Dietrich 2024), elm (drawn at random), library (H as a sparse sum of "
                               "polynomials, sines and cosines of q and products, thresholded as SINDy does: it prints "
                               "as an equation) or sindy (pysindy's dx/dt = Theta(x) Xi, no H: --model baseline, "
                               "optional extra)", choices=FITS, identity_at_default=False)
    library_degree: int = setting(3, "polynomial degree of the library's fields (--fit library, sindy): H's terms go "
                                     "to degree + 1, so that their gradients span the same fields",
                                  parse=cli.int_at_least(1), identity_at_default=False)
    library_frequencies: int = setting(1, "the library's sines and cosines of q at frequencies 1..N (0: none)",
                                       parse=cli.int_at_least(0), identity_at_default=False)
    library_threshold: float = setting(0.05, "the library fits keep a term only where its coefficient is at least "
                                             "this large (SINDy's STLSQ threshold, in the data's units)",
                                       parse=cli.nonnegative_float, identity_at_default=False)
    fit_rcond: float | str = setting("auto", "ridge of the least-squares fits relative to the design's unit-norm "
                                             "columns: auto (chosen by generalized cross-validation, so noisy data "
                                             "are not interpolated) or a number (Sampling-HNNs' exact data: 1e-13, "
                                             "as their numpy lstsq rcond)", parse=cli.auto_or_positive_float,
                                     identity_at_default=False)
    map_layers: int = setting(MAP_LAYERS, "layers of a learned map (--model g_sympnet, la_sympnet, henon: hnn.models.maps)",
                              parse=cli.int_at_least(1), identity_at_default=False)
    snippet_steps: int = setting(4, "time steps per snippet of --objective trajectory (CHNN's 5-state snippets: 4)",
                                 parse=cli.int_at_least(1))
    verbose: bool = setting(False, "print the loss every print_every steps", display_only=True)
    field_type: str = setting("solenoidal", "solenoidal (Hamiltonian), conservative, or both", choices=FIELD_TYPES)
    seed: int = setting(0, "seeds the dataset, the init and the minibatches", parse=cli.int_at_least(0))
    save_dir: str = setting(".", "folder that receives the run folder <name>-<model>-seed<seed>-<hash>/")
    device: str = setting("cpu", "torch device, e.g. cpu, cuda or cuda:1; recorded in args.json, not part of the "
                                 "run's identity (a run trained on a GPU is reused on a CPU, and the other way)",
                          parse=cli.device, identity_value="cpu")
    threads: int = setting(1, "torch threads of a train.py run: a second speeds a step up on an idle box but slows it "
                              "many times over on a shared one (docs/speed.md#threads); args.json records the count "
                              "the run used, which is not part of its identity", parse=cli.int_at_least(1),
                           display_only=True)
    dtype: str = setting("float32", "dtype of the model and the data", choices=DTYPES)
    debug: bool = setting(False, "on an input error (a missing data file, say) or Ctrl-C, show the full traceback "
                                 "instead of one line", display_only=True)
    force: bool = setting(False, "retrain and replace a complete run of the same settings in save_dir, which "
                                 "is otherwise reused", display_only=True)

    # what the state's width measures, for --input_dim's error; the model kinds --model takes
    # (None: every registered kind without a family prefix); the prefix of this task's kinds
    # ("pixel-" for the pixel task's latent models); help texts that differ from the base's
    STATE: ClassVar[str] = "state x = [q, p]"
    MODELS: ClassVar[tuple[str, ...] | None] = None
    KIND_PREFIX: ClassVar[str] = ""
    HELP: ClassVar[dict[str, str]] = {}
    # the fields that dataset() reads: runs that agree on them share one dataset, built once per sweep
    DATASET_FIELDS: ClassVar[tuple[str, ...]] = ("seed",)

    @property
    def kind(self) -> str:
        """The registered model kind (``hnn.MODEL_KINDS``) this run trains: the one place it is worked out."""
        return self.KIND_PREFIX + self.model

    def dataset(self) -> dict:
        """The arrays this run trains on (``self.make_objective().arrays`` and, for ``use_rk4``, ``dt``)."""
        raise NotImplementedError(f"{type(self).__name__} must implement dataset()")

    def check_inputs(self) -> None:
        """Raise one of ``hnn.command.INPUT_ERRORS`` naming the fix when this run's input is missing
        (a data file, say), before torch loads; nothing to check by default."""

    def make_objective(self):
        """What this run fits: the objective its model kind is registered with, or with ``objective=
        'trajectory'`` a ``TrajectoryObjective`` of ``snippet_steps`` (for kinds fit on dx/dt only)."""
        # deferred: the registry loads torch, and a config is parsed before torch (train.py --help)
        from .kinds import OBJECTIVES, get_objective, objective_for
        from .objectives import DerivativeObjective
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective={self.objective!r}: choose one of {', '.join(OBJECTIVES)}")
        registered = objective_for(self.kind)
        if self.derivative_loss != "l2" and not (self.objective == "derivative"
                                                 and isinstance(registered, DerivativeObjective)):
            raise ValueError(f"derivative_loss={self.derivative_loss!r} sets the error of a fit of dx/dt "
                             f"(objective='derivative'); objective={self.objective!r} of the {self.kind} model has "
                             "its own loss: drop derivative_loss")
        if self.balance == "rms" and not (self.objective == "derivative" and isinstance(registered, DerivativeObjective)):
            raise ValueError(f"balance='rms' weighs the components of a fit of dx/dt (objective='derivative'); "
                             f"objective={self.objective!r} of the {self.kind} model has its own loss: drop balance")
        if self.objective == "derivative" or isinstance(registered, OBJECTIVES[self.objective]):
            return registered
        if not isinstance(registered, DerivativeObjective):
            raise ValueError(f"objective={self.objective!r} fits a field of the state, and the {self.kind} model "
                             f"trains with {type(registered).__name__}; use objective='derivative'")
        takes_steps = "steps" in inspect.signature(OBJECTIVES[self.objective]).parameters
        return get_objective(self.objective, **({"steps": self.snippet_steps} if takes_steps else {}))

    def finish(self, directory, dataset: dict) -> None:
        """Called after the run is saved in ``directory`` (the pixel task measures its energy here)."""

    # -- identity ------------------------------------------------------------------------------

    @classmethod
    def display_only(cls) -> tuple[str, ...]:
        """The fields that change what is printed or how fast, never what is trained."""
        return tuple(f.name for f in dataclasses.fields(cls) if cli.field_meta(cls, f.name).get("display_only"))

    def identity(self) -> dict:
        """The fields that decide what is trained: all but the display-only ones, ``save_dir``, and a
        field declared ``identity_at_default=False`` while it holds its default; a field declared with an
        ``identity_value`` holds that value."""
        skip, fixed = set(self.display_only()) | {"save_dir"}, {}
        for f in dataclasses.fields(self):
            meta = cli.field_meta(type(self), f.name)
            if meta.get("identity_at_default") is False and getattr(self, f.name) == f.default:
                skip.add(f.name)
            if meta.get("identity_value", _ANY) is not _ANY:
                fixed[f.name] = meta["identity_value"]
        return {k: fixed.get(k, v) for k, v in dataclasses.asdict(self).items() if k not in skip}

    def key(self) -> str:
        """8 hex digits of the SHA-256 of ``identity()`` as JSON: the last part of the run folder's name."""
        text = json.dumps(self.identity(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:8]

    def dataset_key(self) -> tuple:
        """Equal for runs that train on the same dataset."""
        return (type(self).__module__, type(self).__qualname__) + tuple(getattr(self, name) for name in self.DATASET_FIELDS)

    def model_facts(self) -> dict:
        """What a model kind's build reads that no flag sets, facts the task declares (the chain's
        ``constraints`` graph, for the Cartesian kinds); saved in args.json beside the fields."""
        return {}

    def to_dict(self) -> dict:
        """The fields and the ``model_facts()``: what a run's args.json holds (``from_dict`` reads the fields)."""
        return {**dataclasses.asdict(self), **self.model_facts()}

    @classmethod
    def from_dict(cls, values: dict) -> RunConfig:
        """The config of a saved run's args (keys that are not fields, such as ``kind``, aside)."""
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in values.items() if k in names})
