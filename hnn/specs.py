"""A run's settings, typed: what each consumer of a run reads, derived once from its config or from
a saved run's args (``run_specs``), so that no consumer reads a settings dict by string key.

    specs = hnn.specs.run_specs(config)               # an hnn.RunConfig, or the args.json of a run folder
    model = hnn.kinds.model_from_spec(specs.model)
    options = objective.train_options(model, specs.objective, dataset)
    stats = hnn.train(model, x, y, **specs.training.train_kwargs(), **options.train_kwargs())

Four frozen specs, one per stage (``hnn.settings.STAGES``): ``ModelSpec`` (what a kind's builder reads),
``TrainingSpec`` (what ``hnn.train`` reads, by its keyword names), ``ObjectiveSpec`` (what an objective
reads: ``Objective.train_options``) and ``FitSpec`` (what a least-squares fit reads: ``hnn.fits.solve``).
Their fields are not written here: each is a setting declared with that ``stage`` (``hnn.settings``:
``RunSettings``' fields and the shared ``TASK_SETTINGS``), at its ``absent`` value, the value a run whose
args lack it trained with (a run saved before the field existed, or a task without it, such as
``input_noise`` outside the 2-body and pixel tasks); the model's spec adds the facts a task declares
(``MODEL_FACTS``). A config class that declares a staged field of its own gets specs with it
(``specs_of``). Torch-free; a run's identity and its args.json are the config's (``hnn.RunConfig``),
untouched here.
"""
from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from .settings import RunSettings, stage_fields, task_stage_fields


def _picked(cls, values: Mapping) -> dict:
    """The entries of ``values`` that are fields of dataclass ``cls``."""
    return {f.name: values[f.name] for f in fields(cls) if f.name in values}


class _Spec:
    """What every spec does: read a run's (saved) args."""

    @classmethod
    def from_args(cls, args: Mapping):
        """The spec of a run's (saved) args: its fields, the ``absent`` value of any it lacks."""
        return cls(**_picked(cls, args))


class _ModelReads(_Spec):
    @classmethod
    def from_args(cls, args: Mapping):
        """The spec of a run's (saved) args: its declared fields, the ``absent`` value of any it lacks."""
        if "kind" not in args:
            raise ValueError(f"a run's args need its model's kind to build it; got keys {sorted(args)}")
        values = _picked(cls, args)
        # the measured task's --periodic names the angle columns: a model reads all of its q as angles or none
        if "periodic" in values:
            values["periodic"] = bool(values["periodic"])
        return cls(**values)


class _TrainingReads(_Spec):
    def train_kwargs(self) -> dict[str, Any]:
        """``hnn.train``'s keyword arguments (and ``hnn.trainers.vmap.train_vmap``'s of the same names)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


class _FitReads(_Spec):
    def solve_kwargs(self) -> dict[str, Any]:
        """``hnn.fits.solve``'s keyword arguments."""
        return {"fit": self.fit, "seed": self.seed, "rcond": self.fit_rcond, "threshold": self.library_threshold}


# what a kind's builder reads that no setting declares: the kind (required), and the facts of a task or of
# its data (a config's ``model_facts()`` and ``hnn.policy.saved_args``), None where a task has none
MODEL_FACTS = (("constraints", "dict | None"), ("dt", "float | None"), ("bodies", "dict | None"))

_DOCS = {
    "model": """What a kind's builder reads of a run (a run's ``args.json`` holds these among the rest of its
    config; ``from_args`` picks them out): ``kind`` (a key of ``MODEL_KINDS``), the settings of stage
    ``model`` (``input_dim`` is None in a spec without it: the constrained kinds read theirs from the graph;
    a fit other than ``'adam'`` builds its own model, ``hnn.fits.build``, float64 whatever ``dtype`` says)
    and the facts: ``constraints`` (``ConstraintGraph.to_dict()``, the constrained kinds), ``dt`` (the time
    step of the run's data, a learned map's step) and ``bodies`` (``hnn.bodies.Bodies.to_dict()``, which the
    pair kind reads).""",
    "training": """What ``hnn.train`` reads of a run: its keyword arguments of the same names. The loop's own
    options (``predict``, ``loss``, ``input_noise``, ...) are the objective's (``Objective.train_options``).""",
    "objective": """What an objective reads of a run (``Objective.train_options``); ``seed`` starts the pixel
    objective's noise generator at seed + 2.""",
    "fit": """What a least-squares fit reads of a run (``hnn.fits.solve``'s keywords); ``seed`` draws the
    sampled neurons.""",
}
_BASES = {"model": _ModelReads, "training": _TrainingReads, "objective": _Spec, "fit": _FitReads}
_NAMES = {"model": "ModelSpec", "training": "TrainingSpec", "objective": "ObjectiveSpec", "fit": "FitSpec"}


def _made(name: str, declared: list, bases: tuple, doc: str | None) -> type:
    """A frozen dataclass ``name`` of the ``declared`` ``(name, type, default)`` fields (``MISSING``: none),
    in this module."""
    spec = dataclasses.make_dataclass(name, [(n, t, dataclasses.field(default=d)) for n, t, d in declared],
                                      bases=bases, frozen=True)
    spec.__module__, spec.__qualname__ = __name__, name
    if doc:     # the fields, read off the declaration, so that the list is never stale
        names = ", ".join(f"``{f.name}``" for f in fields(spec))
        spec.__doc__ = f"{doc}\n\n    Its fields (each setting's meaning is its ``--help``, ``hnn.settings``): {names}."
    return spec


def _library_spec(stage: str) -> type:
    """The spec of ``stage``: its declared settings, and for the model its kind (required) and facts."""
    declared = stage_fields(RunSettings, stage) + task_stage_fields(stage)
    if stage == "model":
        declared = [("kind", "str", dataclasses.MISSING), *declared, *((n, t, None) for n, t in MODEL_FACTS)]
    return _made(_NAMES[stage], declared, (_BASES[stage],), _DOCS[stage])


ModelSpec = _library_spec("model")
TrainingSpec = _library_spec("training")
ObjectiveSpec = _library_spec("objective")
FitSpec = _library_spec("fit")
_LIBRARY = {"model": ModelSpec, "training": TrainingSpec, "objective": ObjectiveSpec, "fit": FitSpec}


@functools.cache
def specs_of(config_class: type) -> dict[str, type]:
    """The spec class of each stage for configs of ``config_class``: the library's, or a subclass of it
    with the staged fields that ``config_class`` declares beyond the library's settings."""
    out = {}
    for stage, spec in _LIBRARY.items():
        known = {f.name for f in fields(spec)}
        extra = [row for row in stage_fields(config_class, stage) if row[0] not in known]
        out[stage] = _made(spec.__name__, extra, (spec,), None) if extra else spec
    return out


@dataclass(frozen=True)
class RunSpecs:
    """A run's typed specs: ``model``, ``training``, ``objective``, ``fit``."""
    model: ModelSpec
    training: TrainingSpec
    objective: ObjectiveSpec
    fit: FitSpec = FitSpec()


def run_specs(source) -> RunSpecs:
    """The typed specs of a run: ``source`` is its config (an ``hnn.RunConfig``: its fields, model facts
    and kind, read by its class's specs, ``specs_of``) or a saved run's args (``args.json``, as
    ``hnn.load_run`` returns them, read by the library's)."""
    if isinstance(source, Mapping):
        values, classes = source, _LIBRARY
    elif dataclasses.is_dataclass(source) and hasattr(source, "to_dict"):
        values, classes = {**source.to_dict(), "kind": source.kind}, specs_of(type(source))
    else:
        raise TypeError(f"run_specs reads an hnn.RunConfig or a run's saved args (a dict), got {type(source).__name__}")
    return RunSpecs(*(classes[stage].from_args(values) for stage in ("model", "training", "objective", "fit")))
