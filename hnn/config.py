"""A run is a config: ``RunConfig`` holds every field of a training run, with the original's names.

    config = SpringConfig(total_steps=10, hidden_dim=16)     # a task's subclass (experiment-spring/train.py)
    folder = hnn.run_experiment(config)                     # trains, saves, returns the run folder

A ``RunConfig`` is an ``hnn.settings.RunSettings`` (where each field is declared once: its default, flag
text, value rule, identity and the stages that read it) with the behaviour of a run. A task subclasses
``RunConfig``: it sets its defaults (``name``, ``input_dim``, ``weight_decay``, ...), adds its own fields
(declared with ``hnn.settings.setting``, which gives each its ``--help`` text and how its flag parses, or
``hnn.settings.task_setting`` for a setting a few tasks share), and implements ``dataset()``.
``hnn.cli.parse(SpringConfig, argv)`` builds the command line from the fields, so every field is a flag with
the field's spelling and default.

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
from typing import ClassVar

from . import cli
from .settings import RunSettings


@dataclass
class RunConfig(RunSettings):      # its fields are RunSettings', each declared there once
    """One training run: the original's flags with its defaults, plus the knobs it hard-coded."""

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
            if "identity_value" in meta:
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
