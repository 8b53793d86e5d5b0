"""A run's policy, settled once: ``prepare`` resolves what a config (``hnn.RunConfig``) trains on, the
model, its units, the balance of its loss, how its weights are found, its seed and its training subset,
into a ``Prepared``; every way of training a config (a lone run, ``hnn.run_experiment``; a group's members,
``hnn.sweeps.group_runs``; the studies and benchmarks) starts from it, and ``Prepared.final_losses`` scores
what it trained in the user's units. The resolvers themselves live with what they resolve (``hnn.cli.check``,
``hnn.fits``, ``hnn.kinds``, ``hnn.objectives``, ``hnn.specs``, ``hnn.units``); ``hnn.train``'s front door
calls the same ones for a user's arrays."""
from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass
from typing import Iterator

import numpy as np
import torch

from . import cli
from .fits import check_config
from .io import check_save_dir
from .kinds import get_kind, model_from_spec
from .objectives import LoopOptions, Objective
from .specs import run_specs
from .units import canonical_fit, run_scales, wrap_saved


def _materialize(dataset) -> tuple[dict, float | None]:
    """``(dataset, seconds it took)``: calls a dataset given as a function (None seconds otherwise)."""
    if not callable(dataset):
        return dataset, None
    tic = time.perf_counter()
    dataset = dataset()
    return dataset, time.perf_counter() - tic


@dataclass(frozen=True)
class Prepared:
    """What a run of a config trains, built once (``prepare``): every lone run, benchmark and study that
    trains or times a config's model gets it here, so each trains as ``hnn.run_experiment`` would.

    ``saved``: the args.json it saves (``saved_args``, with ``unit_scales`` and ``loss_weights`` where
    --units and --balance resolved them); ``specs``: ``run_specs(saved)``; ``model``: the model it saves
    (an ``hnn.units.Rescaled`` where --units rescaled); ``canonical_model``: the one that trains (in canonical
    units); ``dataset``: the objective's prepared arrays in the user's units; ``x``, ``y`` (the training
    subset), ``test_x``, ``test_y``: ``canonical_model``'s, ``(rows, input_dim)``; ``options``: the objective's
    ``LoopOptions`` for ``canonical_model`` (``Objective.train_options``); ``data_seconds``: the dataset's build time
    (None when given)."""
    config: object
    objective: Objective
    fit: object
    saved: dict
    specs: object
    model: torch.nn.Module
    canonical_model: torch.nn.Module
    scales: object
    dataset: dict
    x: object
    y: object
    test_x: object
    test_y: object
    options: LoopOptions
    data_seconds: float | None

    def train_kwargs(self, **overrides) -> dict:
        """``hnn.train``'s keyword arguments past the arrays: the run's loop settings and the objective's
        options, --units and --balance already applied (``overrides``: a benchmark's steps, say)."""
        return {**self.specs.training.train_kwargs(), **self.options.train_kwargs(), "units": "off", "balance": "off",
                "threads": None, **overrides}

    def final_losses(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The trained ``model``'s final ``(mean, ±)`` train and test losses (``Objective.final_loss``), in the
        user's units: where --units rescaled, on the dataset as given (its training subset drawn again) with
        the options the objective gives the saved model, else on the rows and options it trained with."""
        x, y, test_x, test_y, options = self.x, self.y, self.test_x, self.test_y, self.options
        if self.scales is not None:
            options = self.objective.train_options(self.model, self.specs.objective, self.dataset)
            x, y, test_x, test_y = (self.dataset[key] for key in self.objective.arrays)
            x, y = training_subset(x, y, self.config.train_fraction, self.config.seed)
        return (self.objective.final_loss(self.model, x, y, options),
                self.objective.final_loss(self.model, test_x, test_y, options))


@contextlib.contextmanager
def seeded(seed: int, device="cpu") -> Iterator[None]:
    """Inside this block torch's and numpy's global generators start from ``seed`` (a model's init draws
    from them: ``hnn.models``); the caller's random state comes back after, however the block ends. On a
    GPU its generator is forked too."""
    state = np.random.get_state()
    cuda = [torch.device(device).index or 0] if torch.device(device).type == "cuda" else []
    try:
        with torch.random.fork_rng(devices=cuda):
            torch.manual_seed(seed)
            np.random.seed(seed)
            yield
    finally:
        np.random.set_state(state)


def prepare(config, dataset=None, objective: Objective | None = None, saves: bool = False) -> Prepared:
    """The model, objective, rows and options that ``config`` (an ``hnn.RunConfig``) trains on (``Prepared``).

    ``dataset`` defaults to ``config.dataset``; it holds the ``objective.arrays`` (default ``x``,
    ``dxdt``, ``test_x``, ``test_dxdt``, ``(rows, input_dim)`` arrays) and, for ``use_rk4``,
    ``dt`` (the time step of its trajectories); or it is a function of no arguments returning that
    dict, whose time is ``data_seconds``. ``objective`` defaults to ``config.make_objective()``.
    A value the config's flag would refuse raises ValueError before anything is built (with ``saves``, a run
    to be saved, a ``save_dir`` that cannot be written too: it is created where missing); the model is
    drawn from ``config.seed`` (``seeded``: the caller's random state is left as it was).

    The one resolver of a run's policy: its units (``hnn.units.run_scales``), the balance of its loss
    (``Objective.train_options``, ``hnn.balance``), how its weights are found (``fit``), its seed and its
    training subset. Every way of training a config goes through it: a lone run (``hnn.run_experiment``), a
    group's members (``hnn.sweeps.group_runs.train_group``) and the studies."""
    cli.check(config)
    if saves:
        check_save_dir(config.save_dir)
    # a least-squares fit refuses what it cannot fit before any data is built
    fit = check_config(config, get_kind(config.kind).coordinates)
    objective = objective or config.make_objective()
    dataset, data_seconds = _materialize(config.dataset if dataset is None else dataset)
    dataset = objective.prepare(dataset)
    missing = [key for key in objective.arrays if key not in dataset]
    if missing:
        raise KeyError(f"dataset lacks {missing}; this task's dataset() must return {list(objective.arrays)}")
    saved = saved_args(config, dataset)
    specs = run_specs(saved)        # the config's, and the data's time step (a learned map's step)
    with seeded(config.seed, config.device):        # the model's init, the caller's random state untouched
        model = model_from_spec(specs.model, config.device)
    scales = run_scales(specs.objective.units, specs.model.kind, dataset, objective, model)
    if scales is not None:      # --units: the model trains in the canonical units of its data (hnn.units)
        saved["unit_scales"] = scales.to_dict()
        model = wrap_saved(model, saved)
    canonical_model, fitted = (model, dataset) if scales is None else canonical_fit(model, dataset, objective.arrays)
    x, y, test_x, test_y = (fitted[key] for key in objective.arrays)
    x, y = training_subset(x, y, config.train_fraction, config.seed)
    options = objective.train_options(canonical_model, specs.objective, fitted)
    if options.loss_weights is not None:     # what --balance resolved to: the run's loss, recorded
        saved["loss_weights"] = [float(w) for w in options.loss_weights]
    return Prepared(config, objective, fit, saved, specs, model, canonical_model, scales, dataset, x, y, test_x, test_y,
                    options, data_seconds)


def saved_args(config, dataset: dict) -> dict:
    """What a run's args.json holds: the config's fields and model facts, the kind, the threads it trains
    on (as torch has them: a train.py sets ``config.threads``, a sweep or a caller its own), the
    cached dataset it reads (a lone run and a group's member alike) and its time step ``dt`` where it
    has one (a learned map's step: ``hnn.specs.ModelSpec.dt``)."""
    return {**config.to_dict(), "threads": torch.get_num_threads(), "kind": config.kind,
            "dataset_cache_key": dataset.get("cache_key"),
            **({"dt": float(dataset["dt"])} if dataset.get("dt") is not None else {})}


def training_subset(x, y, fraction: float, seed: int):
    """The first ``ceil(fraction * rows)`` of a seeded permutation of the training rows (kept in
    their original order), or ``(x, y)`` themselves for ``fraction`` 1. The draw has its own
    generator, so the init and the minibatches see the same random streams at every fraction."""
    if not 0 < fraction <= 1:
        raise ValueError(f"train_fraction must be in (0, 1], got {fraction!r}")
    if fraction == 1:
        return x, y
    rows = len(x)
    keep = np.sort(np.random.default_rng(seed).permutation(rows)[:max(1, math.ceil(fraction * rows))])
    return x[keep], y[keep]
