"""A run: train one model from its config (``hnn.RunConfig``), and save / load it.

A run folder ``<save_dir>/<name>-<model>-seed<seed>-<key>/`` (``key``: the short hash of the
config's identity, ``RunConfig.key``) holds ``model.tar`` (state dict and args; loads with
``weights_only=True``), ``args.json`` (the config, its model ``kind`` and its dataset's
``dataset_cache_key``), ``metrics.json`` and, written last, ``complete.json``. The folder is
written as a whole: filled under a hidden temporary name beside it, then renamed into place, so
a crash leaves the complete old run, the complete new one, or no folder, never a checkpoint of
one run beside the args of another. Later files (a pixel run's ``rollout.npz`` and GIFs) are
added to the finished folder one by one. While a run trains, its loop's checkpoint sits beside the
folder-to-be as ``<save_dir>/.<folder>.partial.pt`` (``partial_checkpoint``): a run killed or
interrupted (Ctrl-C) resumes from it when started again with the same settings, and it is deleted
when the run is saved, when training fails, and by ``--force``.
"""
from __future__ import annotations

import contextlib
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import torch

from . import cli
from .fits import check_config
from .io import atomic_folder, check_save_dir, torch_bytes, write_json
from .kinds import get_kind, model_from_args, model_from_spec
from .objectives import LoopOptions, Objective
from .specs import run_specs
from .trainers.least_squares import solve_prepared
from .trainers.lone import train_prepared
from .units import canonical_fit, run_scales, wrap_saved


def run_label(config) -> str:
    """The middle of a run folder's name: its model kind as ``--model`` names it (``config.model``: the
    kind without a task's prefix such as ``pixel-``), ``+<fit>`` where a least-squares ``--fit`` found its
    weights (``hnn+library``: a run of the training loop, the default, keeps the name it always had), and
    ``-rk4`` for ``use_rk4``."""
    return kind_label(config.model, config.fit) + ("-rk4" if config.use_rk4 else "")


def kind_label(model: str, fit: str = "adam") -> str:
    """What a run is, in a word: its kind ``model``, with ``+<fit>`` where ``fit`` is not the training loop
    (``hnn+library``, ``hnn+swim``; ``hnn`` for ``adam``). Read by run folders and ``analysis/score.py``."""
    return model if fit in (None, "adam") else f"{model}+{fit}"


def run_dir(config) -> Path:
    """Where the run of this config lives: ``<save_dir>/<name>-<model>-seed<seed>-<key>``, ``<model>``
    being ``run_label``'s (the kind as ``--model`` names it)."""
    return Path(config.save_dir) / f"{config.name}-{run_label(config)}-seed{config.seed}-{config.key()}"


# written last into a run folder: one without it is an interrupted save
COMPLETE = "complete.json"


def diverged_record(config) -> Path:
    """Where the run of ``config`` is recorded as failed in training by its own arithmetic (an
    ``hnn.DivergenceError``: a result of its config, which a rerun repeats): ``<save_dir>/.<folder>.diverged.json``
    holding its message. Written where the run fails (``hnn.tasks.run_task``, a sweep's worker) and by the
    sweep that reads the failure; ``hnn.sweeps.sweep.reuse(jobs, diverged=True)`` reads it back instead of
    training the run again."""
    directory = run_dir(config)
    return directory.parent / f".{directory.name}.diverged.json"


def record_divergence(config, err: BaseException) -> None:
    """Record the run of ``config`` as failed in training by ``err`` (``diverged_record``: its type and message)."""
    write_json(diverged_record(config), {"message": f"{type(err).__name__}: {err}"})


def partial_checkpoint(config) -> Path:
    """The training checkpoint of this config's run while it trains (``hnn.train(checkpoint=...)``)."""
    directory = run_dir(config)
    return directory.parent / f".{directory.name}.partial.pt"


def is_complete(directory: Path) -> bool:
    """Whether ``directory`` holds a completion mark and every file it lists."""
    try:
        files = json.loads((directory / COMPLETE).read_text())["files"]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return all((directory / name).is_file() for name in files)


def find_run(config) -> Path | None:
    """The complete saved run of this config, or None: a lookup of its folder."""
    directory = run_dir(config)
    return directory if is_complete(directory) else None


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
    trains or times a config's model gets it here, so each trains as ``run_experiment`` would.

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


def prepare(config, dataset=None, objective: Objective | None = None) -> Prepared:
    """The model, objective, rows and options that ``config`` (an ``hnn.RunConfig``) trains on (``Prepared``).

    ``dataset`` defaults to ``config.dataset``; it holds the ``objective.arrays`` (default ``x``,
    ``dxdt``, ``test_x``, ``test_dxdt``, ``(rows, input_dim)`` arrays) and, for ``use_rk4``,
    ``dt`` (the time step of its trajectories); or it is a function of no arguments returning that
    dict, whose time is ``data_seconds``. ``objective`` defaults to ``config.make_objective()``.
    A value the config's flag would refuse raises ValueError before anything is built; the model is
    drawn from ``config.seed`` (``seeded``: the caller's random state is left as it was).

    The one resolver of a run's policy: its units (``hnn.units.run_scales``), the balance of its loss
    (``Objective.train_options``, ``hnn.balance``), how its weights are found (``fit``), its seed and its
    training subset. Every way of training a config goes through it: a lone run (``run_experiment``), a
    group's members (``hnn.sweeps.group_runs.train_group``) and the studies."""
    cli.check(config)
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


def run_experiment(config, dataset=None, objective: Objective | None = None,
                   on_step: Callable[[int, int], None] | None = None) -> Path:
    """Train the model that ``config`` (an ``hnn.RunConfig``) describes and save the run; returns
    its folder. Every task and model kind trains here, on what ``prepare(config, dataset, objective)``
    builds (its arguments: ``prepare``'s; ``on_step(done, total)`` after each step of its loop: a sweep's
    bar, or a study that stops a run by raising); a ``dataset`` given as a function has its time saved as
    ``data_seconds`` in ``metrics.json`` beside ``train_seconds`` (the training loop alone).
    """
    cli.check(config)
    check_save_dir(config.save_dir)
    prep = prepare(config, dataset, objective)
    objective, saved, specs, model, scales, dataset = (prep.objective, prep.saved, prep.specs, prep.model,
                                                       prep.scales, prep.dataset)
    x, y, test_x, test_y, options = prep.x, prep.y, prep.test_x, prep.test_y, prep.options
    partial = partial_checkpoint(config)
    if config.force:
        partial.unlink(missing_ok=True)
    try:
        # one linear solve (hnn.fits), not a loop: nothing to checkpoint; else the lone loop on what prepare
        # resolved (--units, --balance on the whole training set, recorded in args.json; the threads it was given)
        stats = solve_prepared(prep) if prep.fit.solved else train_prepared(prep, checkpoint=partial, on_step=on_step)
    except Exception:       # a failure repeats from the checkpoint; an interrupt (not an Exception) keeps it
        partial.unlink(missing_ok=True)
        raise
    if scales is not None:      # the final numbers: the saved model's, in the user's units
        options = objective.train_options(model, specs.objective, dataset)
        x, y, test_x, test_y = (dataset[key] for key in objective.arrays)
        x, y = training_subset(x, y, config.train_fraction, config.seed)
    directory = finish_run(config, model, stats, objective.final_loss(model, x, y, options),
                           objective.final_loss(model, test_x, test_y, options), prep.data_seconds, saved)
    partial.unlink(missing_ok=True)
    config.finish(directory, dataset)
    return directory


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


def finish_run(config, model, stats: dict, train_loss, test_loss, data_seconds: float | None,
               saved_args: dict) -> Path:
    """Print (with ``verbose``) and save a trained run: its final ``(mean, ±)`` train and test
    losses, the seconds of its data and of its loop, and the loss history ``stats``.
    ``saved_args`` is what args.json holds."""
    if config.verbose:
        print(f"Final train loss {train_loss[0]:.4e} +/- {train_loss[1]:.4e}\n"
              f"Final test loss {test_loss[0]:.4e} +/- {test_loss[1]:.4e}")
    metrics = {"train_loss": train_loss[0], "train_loss_se": train_loss[1],
               "test_loss": test_loss[0], "test_loss_se": test_loss[1],
               "data_seconds": data_seconds, "train_seconds": stats["seconds"], "history": stats}
    return save_run(run_dir(config), model, saved_args, metrics)


def save_run(directory, model: torch.nn.Module, args: dict, metrics: dict) -> Path:
    """Write ``model.tar``, ``args.json``, ``metrics.json`` and last ``complete.json`` as a new
    folder ``directory``, replacing any folder there only once all are written."""
    directory = Path(directory)
    args = {k: v for k, v in args.items()}
    # the float reduction order, hence the last bits of every number, depends on the thread count
    metrics = {**metrics, "torch_threads": torch.get_num_threads()}
    # tensors, and a rescaled model's scales (its extra state, a dict of numbers)
    state = {k: v.detach().cpu() if torch.is_tensor(v) else v for k, v in model.state_dict().items()}

    def fill(tmp: Path) -> None:
        (tmp / "model.tar").write_bytes(torch_bytes({"state_dict": state, "args": args}))
        write_json(tmp / "args.json", args)
        write_json(tmp / "metrics.json", metrics)
        write_json(tmp / COMPLETE, {"files": ["model.tar", "args.json", "metrics.json"]})

    atomic_folder(directory, fill)
    return directory


def load_run(directory, device: torch.device | str = "cpu") -> tuple[torch.nn.Module, dict, dict]:
    """``(model in eval mode, args, metrics)`` of a saved run, its model on ``device`` (the run's
    recorded device is where it trained, not where it must be read: a GPU's run loads on a CPU)."""
    directory = Path(directory)
    ckpt = directory / "model.tar"
    if not ckpt.exists():
        raise FileNotFoundError(f"no checkpoint at {ckpt}; train it first (see the task's train.py)")
    if not is_complete(directory):
        raise RuntimeError(f"run folder {directory} lacks {COMPLETE} or a file it lists: its save was interrupted "
                           "; delete the folder and retrain")
    try:
        blob = torch.load(ckpt, map_location="cpu", weights_only=True)
        model = model_from_args(blob["args"])
        model.load_state_dict(blob["state_dict"])
        model = model.to(device)
    except Exception as err:
        # torch's own message advises weights_only=False, which would run code from the file
        raise RuntimeError(f"{ckpt} does not load ({type(err).__name__}); delete the folder {directory} and "
                           "retrain") from err
    metrics_path = directory / "metrics.json"
    metrics = json.loads(metrics_path.read_text()) if metrics_path.exists() else {}
    return model.eval(), blob["args"], metrics
