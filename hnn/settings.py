"""Every setting of a run, declared once: its name, default, flag text, value rule, choices, identity and
the stages that read it, in one dataclass (``RunSettings``, CleanRL's one ``Args``, with our checks), from
which the rest follows:

- the config: ``hnn.RunConfig`` is a ``RunSettings`` (a task's config subclasses it, declaring its own
  fields with ``setting`` and changing defaults by plain assignment);
- the flags: ``hnn.cli`` makes one flag per field, with its help, value rule and choices;
- the identity: ``RunConfig.identity`` reads each field's ``display_only``, ``identity_at_default`` and
  ``identity_value``;
- the specs: ``hnn.specs`` gives each stage (``STAGES``) a frozen spec of the fields declared with that
  ``stage``; a spec's default is the field's ``absent`` value (what a run whose args lack the field trained
  with: by default its default);
- the library's defaults: ``hnn.train``, the models and the fits take theirs from here
  (``RunSettings.hidden_dim``, ...), so a function called in Python answers as the command does.

A setting is one line in ``RunSettings`` (or one row of ``TASK_SETTINGS`` for one that a few tasks declare
and a stage reads, such as the pixel task's ``latent_dim``: a task's field of it is ``task_setting(name)``).
The value rules (``int_at_least``, ``positive_float``, ...) are argparse types, here so that a setting's
rule is declared with it. Torch-free: ``--help`` answers before torch loads.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .names import (BALANCES, DERIVATIVE_LOSSES, DTYPES, FIELD_TYPES, FITS, INITS, LNN_SOLVES, NONLINEARITIES,
                    OBJECTIVES, OPTIMIZERS, SCHEDULES, UNITS)

# the stages that read a run's settings, each through its spec (hnn.specs): the model kind's builder
# (ModelSpec), hnn.train (TrainingSpec), the objective (ObjectiveSpec) and the least-squares fit (FitSpec)
STAGES = ("model", "training", "objective", "fit")


_UNSET = object()       # a keyword of setting() not given


def setting(default: Any, help: str, *, stage: str | tuple[str, ...] = (), absent: Any = _UNSET, parse=None,
            choices=None, display_only: bool = False, identity_at_default: bool = True,
            identity_value: Any = _UNSET) -> Any:
    """A run's field, declared once (a dataclass field of a config class).

    ``help``: its flag's text; ``parse(text) -> value``: its value rule (an argparse ``type``, default: the
    type of ``default``), checked on the command line and on a config built in Python (``hnn.cli.check``);
    ``choices`` and ``display_only`` (what is printed or how fast, never what is trained: not in the identity)
    as in argparse. ``stage``: the stages (``STAGES``) that read it, each from its spec (``hnn.specs``);
    ``absent``: the value a spec takes for a run whose args lack the field (a run saved before the field
    existed trained with it; default: ``default``). A task that redeclares a field (a new default, help or
    rule) keeps the first declaration's stages and ``absent``.
    ``identity_at_default=False``: a field added after runs were saved, which enters a run's identity only
    when set away from its default, so every run saved before it keeps its folder and is reused.
    ``identity_value=v``: a field that changes where a run trains, not what it trains (the device), which
    the identity records as ``v`` whatever it holds: a run is the same run on every device, and the keys
    saved while the field was part of the identity stay valid."""
    stages = (stage,) if isinstance(stage, str) else tuple(stage)
    unknown = [s for s in stages if s not in STAGES]
    if unknown:
        raise ValueError(f"stage={stage!r}: {unknown} are not stages; choose from {', '.join(STAGES)}")
    return dataclasses.field(default=default, metadata={
        "help": help, "parse": parse, "choices": choices, "display_only": display_only,
        "identity_at_default": identity_at_default, "stage": stages, "absent": default if absent is _UNSET else absent,
        **({} if identity_value is _UNSET else {"identity_value": identity_value})})


def first_declaration(cls: type, name: str) -> dict:
    """The ``setting`` metadata of field ``name`` where a class of ``cls``'s ancestry first declared it: its
    stages and ``absent`` value, which a task that redeclares the field does not change."""
    for klass in reversed(cls.__mro__):
        found = getattr(klass, "__dataclass_fields__", {}).get(name)
        if found is not None and found.metadata:
            return dict(found.metadata)
    return {}


def stage_fields(cls: type, stage: str) -> list[tuple[str, Any, Any]]:
    """``(name, type, absent value)`` of each field of config class ``cls`` that ``stage`` reads, in
    declaration order."""
    out = []
    for f in dataclasses.fields(cls):
        meta = first_declaration(cls, f.name)
        if stage in meta.get("stage", ()):
            out.append((f.name, f.type, meta["absent"]))
    return out


# ----------------------------------------------------------------------------------------------
# argparse types: each turns the flag's text into a value or raises a one-line error that says
# what is wanted (argparse prefixes "argument --flag: ")


def int_at_least(low: int, *, even: bool = False, why: str = "") -> Callable[[str], int]:
    """An argparse ``type``: an integer >= ``low`` (and even, if ``even``); ``why`` explains the rule."""
    rule = f"an {'even ' if even else ''}integer >= {low}{why}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < low or (even and value % 2):
            raise argparse.ArgumentTypeError(f"must be {rule}, got {text!r}")
        return value

    return parse


def _finite_float(text: str, rule: str, ok: Callable[[float], bool]) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and ok(value)):
        raise argparse.ArgumentTypeError(f"must be a finite number {rule}, got {text!r}")
    return value


def positive_float(text: str) -> float:
    """An argparse ``type``: a finite number > 0."""
    return _finite_float(text, "> 0", lambda v: v > 0)


def auto_or_positive_float(text: str) -> float | str:
    """An argparse ``type``: ``auto`` (the program chooses) or a finite number > 0."""
    return "auto" if text == "auto" else _finite_float(text, "> 0, or auto", lambda v: v > 0)


def nonnegative_float(text: str) -> float:
    """An argparse ``type``: a finite number >= 0."""
    return _finite_float(text, ">= 0", lambda v: v >= 0)


def fraction(text: str) -> float:
    """An argparse ``type``: a finite number in (0, 1]."""
    return _finite_float(text, "in (0, 1]", lambda v: 0 < v <= 1)


def optional_int(text: str) -> int | None:
    """``--batch_size``: a positive integer, or none/0/full for the full batch (None)."""
    if text.lower() in ("none", "0", "full"):
        return None
    return int_at_least(1, why=", or none/0/full for the full batch")(text)


def device(text: str) -> str:
    """``--device``: a torch device string this machine has (kept as text: it is saved in args.json).
    The default, cpu, is taken without loading torch."""
    if text == "cpu":
        return text
    import torch     # only to check a device other than the cpu
    try:
        found = torch.device(text)
    except RuntimeError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a torch device; use e.g. cpu, cuda or cuda:1") from None
    backend = getattr(torch, found.type, None)     # torch.cuda, torch.mps, ...: None for exotic types
    if found.type != "cpu" and backend is not None and not backend.is_available():
        raise argparse.ArgumentTypeError(f"{text!r}: this torch build sees no {found.type} device; use --device cpu")
    if found.type != "cpu" and found.index is not None and backend is not None \
            and found.index >= backend.device_count():
        raise argparse.ArgumentTypeError(f"{text!r}: only {backend.device_count()} {found.type} device(s) here, "
                                         "numbered from 0")
    return text



# ----------------------------------------------------------------------------------------------
# the declaration


@dataclass
class RunSettings:
    """One training run: the original's flags with its defaults, plus the knobs it hard-coded."""
    input_dim: int = setting(2, "width of the state x = [q, p] (fixed by the task)", stage="model", absent=None)
    hidden_dim: int = setting(200, "hidden units per layer of the MLP (of the sampled layer with --fit swim or elm)",
                              parse=int_at_least(1), stage="model")
    learn_rate: float = setting(1e-3, "Adam learning rate", parse=positive_float, stage="training")
    weight_decay: float = setting(1e-4, "Adam weight decay (hard-coded per task in the original)",
                                  parse=nonnegative_float, stage="training")
    optimizer: str = setting("adam", "adam (weight decay added to the gradient, the paper's) or adamw (decoupled "
                                     "weight decay, CHNN's)", choices=OPTIMIZERS, stage="training")
    schedule: str = setting("constant", "learning rate over the run: constant (the paper's) or cosine (annealed "
                                        "to 0 at the last step, CHNN's)", choices=SCHEDULES, stage="training")
    clip_grad: float = setting(0.0, "clip each step's gradient to this global norm (0: never); for runs whose "
                                    "loss spikes, such as rollouts through long snippets", parse=nonnegative_float,
                               stage="training")
    batch_size: int | None = setting(None, "minibatch size; none/0/full = full batch", parse=optional_int,
                                     stage="training")
    train_fraction: float = setting(1.0, "train on this fraction of the training rows, drawn once from the seed "
                                         "(the test set stays whole); for studies of how much data a model needs",
                                    parse=fraction)
    nonlinearity: str = setting("tanh", "activation of the MLP", choices=NONLINEARITIES, stage="model")
    init: str = setting("orthogonal", "how the MLPs' weights start: orthogonal (the paper's: orthogonal weights, "
                                      "torch's default biases), zero_bias (DGNet's: orthogonal weights, zero biases), "
                                      "lnn (the LNN's: scaled normal weights, zero biases) or lnn_convex (the LNN's with nonnegative weights after "
                                      "the first layer: with softplus, L convex in qdot at step 0, so its first steps "
                                      "train)", choices=INITS,
                        identity_at_default=False, stage="model")
    lnn_solve: str = setting("solve", "how the lagrangian kind solves d2L/dqdot2 qddot = ... for qddot: solve (stops with "
                                      "an error naming the states where d2L/dqdot2 is singular) or pinv (the LNN authors' "
                                      "pseudo-inverse there, which trains on through them); read by that kind only",
                             choices=LNN_SOLVES, identity_at_default=False, stage="model")
    total_steps: int = setting(2000, "optimizer steps; the loop runs total_steps + 1, as the original",
                               parse=int_at_least(0), stage="training")
    print_every: int = setting(200, "print (and test) every N steps; changes what is printed and the test loss's "
                                    "sampling in metrics.json, never what is trained", parse=int_at_least(1),
                               display_only=True, stage="training")
    name: str = setting("run", "run name, the prefix of the run folder")
    model: str = setting("hnn", "model kind (a row of hnn.MODEL_KINDS describes each)")
    use_rk4: bool = setting(False, "fit the RK4 average slope of the learned field over one data time step dt, "
                                   "(x(t+dt) - x(t))/dt of one RK4 step, to the true dx/dt (the original crashed on "
                                   "this flag); default: fit dx/dt itself", stage="objective")
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
                                   identity_at_default=False, stage="objective")
    balance: str = setting("auto", "weigh each component of dx/dt in the fit's loss by its RMS over the training "
                                   "targets, so no unit decides what is learned (--objective derivative): rms (always), "
                                   "off (the paper's plain loss) or auto (rms where the largest component's RMS exceeds "
                                   "the smallest's over 10x: hnn.balance)", choices=BALANCES, identity_at_default=False,
                           stage="objective", absent="off")    # a run saved before the field trained unbalanced
    # the default moved from off to auto, which trains every task's default data as off did (hnn.units,
    # AUTO_FAR): identity_at_default=False keeps each saved run's key, and off now names its own; a run saved
    # before the field trained in the data's units (absent="off")
    units: str = setting("auto", "train in the canonical units of the data (q / s_q, p / s_p, t / s_t, the RMS sizes of the "
                                 "training data, so Hamilton's equations keep their form) and save a model that answers in "
                                 "the data's units: auto (where the RMS of q or p lies outside [0.1, 10] or that of a "
                                 "rate outside [0.01, 100]: hnn.units), on (always) or off (the data's units)", choices=UNITS,
                         identity_at_default=False, stage="objective", absent="off")
    fit: str = setting("adam", "how the weights are found: adam (the training loop, the paper's) or one least-squares "
                               "solve of dx/dt in float64 (hnn.fits; the hnn, separable, baseline and pairwise kinds, the "
                               "last over radial features of the pairs' distances): swim (a "
                               "hidden layer of --hidden_dim tanh neurons drawn from pairs of training states, Rahma, "
                               "Datar & Dietrich 2024), elm (drawn at random), library (H as a sparse sum of "
                               "polynomials, sines and cosines of q and products, thresholded as SINDy does: it prints "
                               "as an equation) or sindy (pysindy's dx/dt = Theta(x) Xi, no H: --model baseline, "
                               "optional extra)", choices=FITS, identity_at_default=False, stage=("model", "fit"))
    library_degree: int = setting(3, "polynomial degree of the library's fields (--fit library, sindy): H's terms go "
                                     "to degree + 1, so that their gradients span the same fields",
                                  parse=int_at_least(1), identity_at_default=False, stage="model")
    library_frequencies: int = setting(1, "the library's sines and cosines of q at frequencies 1..N (0: none)",
                                       parse=int_at_least(0), identity_at_default=False, stage="model")
    library_threshold: float = setting(0.05, "the library fits keep a term only where its coefficient is at least "
                                             "this large (SINDy's STLSQ threshold, in the data's units)",
                                       parse=nonnegative_float, identity_at_default=False, stage="fit")
    fit_rcond: float | str = setting("auto", "ridge of the least-squares fits relative to the design's unit-norm "
                                             "columns: auto (chosen by generalized cross-validation, so noisy data "
                                             "are not interpolated) or a number (Sampling-HNNs' exact data: 1e-13, "
                                             "as their numpy lstsq rcond)", parse=auto_or_positive_float,
                                     identity_at_default=False, stage="fit")
    map_layers: int = setting(4, "layers of a learned map (--model g_sympnet, la_sympnet, henon: hnn.models.maps)",
                              parse=int_at_least(1), identity_at_default=False, stage="model")
    snippet_steps: int = setting(4, "time steps per snippet of --objective trajectory (CHNN's 5-state snippets: 4)",
                                 parse=int_at_least(1))
    verbose: bool = setting(False, "print the loss every print_every steps", display_only=True, stage="training")
    field_type: str = setting("solenoidal", "solenoidal (Hamiltonian), conservative, or both", choices=FIELD_TYPES,
                              stage="model")
    seed: int = setting(0, "seeds the dataset, the init and the minibatches", parse=int_at_least(0),
                        stage=("training", "objective", "fit"))
    save_dir: str = setting(".", "folder that receives the run folder <name>-<model>-seed<seed>-<hash>/")
    device: str = setting("cpu", "torch device, e.g. cpu, cuda or cuda:1; recorded in args.json, not part of the "
                                 "run's identity (a run trained on a GPU is reused on a CPU, and the other way)",
                          parse=device, identity_value="cpu")
    threads: int = setting(1, "torch threads of a train.py run: a second speeds a step up on an idle box but slows it "
                              "many times over on a shared one (docs/speed.md#threads); args.json records the count "
                              "the run used, which is not part of its identity", parse=int_at_least(1),
                           display_only=True)
    dtype: str = setting("float32", "dtype of the model and the data", choices=DTYPES, stage="model")
    debug: bool = setting(False, "on an input error (a missing data file, say) or Ctrl-C, show the full traceback "
                                 "instead of one line", display_only=True)
    force: bool = setting(False, "retrain and replace a complete run of the same settings in save_dir, which "
                                 "is otherwise reused", display_only=True)


# settings that a few tasks declare and a stage reads (a task's field of one is ``task_setting(name)``), with
# the type a spec gives them: a spec holds each, at its default for a run of another task (the value that
# run trained with), so a saved run of any task rebuilds
TASK_SETTINGS: dict[str, dict[str, Any]] = {
    "latent_dim": dict(type="int", default=2, help="width of the latent state z = [q, p]", stage="model",
                       parse=int_at_least(2, even=True, why=" (z = [q, p])")),
    "ae_nonlinearity": dict(type="str", default="relu", help="activation of the autoencoder", stage="model",
                            choices=NONLINEARITIES),
    "input_noise": dict(type="float", default=0.0, stage="objective", parse=nonnegative_float,
                        help="std of Gaussian noise added to each training batch's inputs"),
    # the measured task's names the angle columns (a string); ModelSpec reads any of them as a bool
    "periodic": dict(type="bool", default=False, stage="model",
                     help="the mechanical and second-order networks see (cos q, sin q): q are angles"),
    # the gravity task's Plummer length: its data's V and the pair kind's radial library read the same e (0, every
    # other task's: no softened term, the library as it was)
    "softening": dict(type="float", default=0.0, stage="model", parse=nonnegative_float,
                      help="Plummer softening length e of V = -1 / sqrt(r^2 + e^2); 0 is Newton's"),
}


def task_setting(name: str, **changes) -> Any:
    """A task's field of the shared setting ``name`` (a key of ``TASK_SETTINGS``), with ``changes`` to its
    ``default``, ``help``, ``parse``, ...; its stages and ``absent`` value are the shared declaration's."""
    if name not in TASK_SETTINGS:
        raise ValueError(f"{name!r} is not a shared task setting; choose one of {', '.join(TASK_SETTINGS)}, or "
                         "declare the task's own field with setting()")
    if {"type", "stage", "absent"} & set(changes):
        raise ValueError(f"task_setting({name!r}): its type, stage and absent value are the shared declaration's; "
                         "drop type=, stage= and absent=")
    declared = {k: v for k, v in TASK_SETTINGS[name].items() if k != "type"}
    return setting(**{**declared, **changes}, absent=declared["default"])


def task_stage_fields(stage: str) -> list[tuple[str, Any, Any]]:
    """``(name, type, absent value)`` of each shared task setting that ``stage`` reads."""
    return [(name, row["type"], row["default"]) for name, row in TASK_SETTINGS.items()
            if stage in ((row["stage"],) if isinstance(row["stage"], str) else row["stage"])]
