"""A run: train one model from parsed flags, and save / load it.

A run folder ``<save_dir>/<name>-<label>-seed<seed>/`` holds ``model.tar`` (state dict and
args; loads with ``weights_only=True``), ``args.json``, ``metrics.json`` and, written last,
``complete.json``. The folder is written as a whole: filled under a hidden temporary name
beside it, then renamed into place, so a crash leaves the complete old run, the complete new
one, or no folder, never a checkpoint of one run beside the args of another. Later files
(a pixel run's ``rollout.npz`` and GIFs) are added to the finished folder one by one.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import torch

from . import cli
from .io import atomic_folder, atomic_write, write_json  # noqa: F401  (hnn.runs.atomic_write, as before)
from .objectives import DerivativeObjective, Objective, model_from_args
from .training import train

def run_label(args) -> str:
    # the kind as its task's --model names it: a recorded family prefix ("pixel-") is the task's own
    kind = (getattr(args, "model", None) or ("baseline" if args.baseline else "hnn")).rsplit("-", 1)[-1]
    return kind + ("-rk4" if getattr(args, "use_rk4", False) else "")


def run_dir(args) -> Path:
    """Where the run for these args lives: ``<save_dir>/<name>-<label>-seed<seed>``."""
    return Path(args.save_dir) / f"{args.name}-{run_label(args)}-seed{args.seed}"


# written last into a run folder: one without it is an interrupted save (or predates this mark)
COMPLETE = "complete.json"


def _is_complete(directory: Path) -> bool:
    """Whether ``directory`` holds a completion mark and every file it lists."""
    try:
        files = json.loads((directory / COMPLETE).read_text())["files"]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return all((directory / name).is_file() for name in files)


# what a run adds to its flags in args.json: its model kind and its dataset's cache file (or None)
RECORDED = ("model", "dataset_cache_key")
# flags added after runs were saved: a saved run without one of them was trained with its default
ADDED_FLAGS = {"train_fraction": 1.0, "split": "original"}


def find_run(args) -> Path | None:
    """The saved run for exactly these args, or None.

    Display-only flags (``args.display_only``, which ``hnn.cli`` parsers fill from the flags
    declared ``display_only=True``; else ``hnn.cli.DISPLAY_ONLY``) and the ``RECORDED`` keys aside.
    """
    directory = run_dir(args)
    try:
        saved = json.loads((directory / "args.json").read_text())
    except (OSError, ValueError):
        return None
    ignore = set(getattr(args, "display_only", cli.DISPLAY_ONLY)) | set(RECORDED)
    wanted = {k: v for k, v in vars(args).items() if k not in ignore}
    saved = {**ADDED_FLAGS, **{k: v for k, v in saved.items() if k not in ignore}}
    wanted = {**ADDED_FLAGS, **wanted}
    if saved != wanted or not _is_complete(directory):
        return None
    return directory


def _materialize(dataset) -> tuple[dict, float | None]:
    """``(dataset, seconds it took)``: calls a dataset given as a function (None seconds otherwise)."""
    if not callable(dataset):
        return dataset, None
    tic = time.perf_counter()
    dataset = dataset()
    return dataset, time.perf_counter() - tic


def run_experiment(args, dataset, objective: Objective | None = None) -> Path:
    """Train the model that ``args`` and ``objective`` describe on ``dataset`` and save the run;
    returns its folder. Every task and model kind trains here.

    ``dataset`` holds the ``objective.arrays`` (default ``x``, ``dxdt``, ``test_x``, ``test_dxdt``,
    ``(rows, input_dim)`` arrays) and, for ``--use_rk4``, ``dt`` (the time step of its
    trajectories); or it is a function of no arguments returning that dict, and then the time it
    takes is saved as ``data_seconds`` in ``metrics.json`` beside ``train_seconds`` (the training
    loop alone). ``objective`` defaults to ``DerivativeObjective()`` (fit dx/dt). args.json
    records the model kind (``"model"``) and the dataset's ``cache_key`` (``"dataset_cache_key"``).
    """
    objective = objective or DerivativeObjective()
    dataset, data_seconds = _materialize(dataset)
    missing = [key for key in objective.arrays if key not in dataset]
    if missing:
        raise KeyError(f"dataset lacks {missing}; this task's get_dataset must return {list(objective.arrays)}")
    saved = {**vars(args), "model": objective.kind(vars(args)), "dataset_cache_key": dataset.get("cache_key")}
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    model = objective.build(saved).to(args.device)
    x, y, test_x, test_y = (dataset[key] for key in objective.arrays)
    x, y = training_subset(x, y, getattr(args, "train_fraction", 1.0), args.seed)
    stats = train(model, x, y, test_x, test_y, total_steps=args.total_steps, learn_rate=args.learn_rate,
                  weight_decay=args.weight_decay, batch_size=args.batch_size, seed=args.seed,
                  print_every=args.print_every, verbose=args.verbose,
                  **objective.train_options(model, saved, dataset))
    return finish_run(args, model, stats, objective.final_loss(model, x, y), objective.final_loss(model, test_x, test_y),
                      data_seconds, saved)


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


def finish_run(args, model, stats: dict, train_loss, test_loss, data_seconds: float | None = None,
               saved_args: dict | None = None) -> Path:
    """Print (with ``--verbose``) and save a trained run: its final ``(mean, ±)`` train and test
    losses, the seconds of its data and of its loop, and the loss history ``stats``.
    ``saved_args`` (default ``vars(args)``) is what args.json holds."""
    if args.verbose:
        print(f"Final train loss {train_loss[0]:.4e} +/- {train_loss[1]:.4e}\n"
              f"Final test loss {test_loss[0]:.4e} +/- {test_loss[1]:.4e}")
    metrics = {"train_loss": train_loss[0], "train_loss_se": train_loss[1],
               "test_loss": test_loss[0], "test_loss_se": test_loss[1],
               "data_seconds": data_seconds, "train_seconds": stats["seconds"], "history": stats}
    return save_run(run_dir(args), model, saved_args or vars(args), metrics)


def save_run(directory, model: torch.nn.Module, args: dict, metrics: dict) -> Path:
    """Write ``model.tar``, ``args.json``, ``metrics.json`` and last ``complete.json`` as a new
    folder ``directory``, replacing any folder there only once all are written."""
    directory = Path(directory)
    args = {k: v for k, v in args.items()}
    # the float reduction order, hence the last bits of every number, depends on the thread count
    metrics = {**metrics, "torch_threads": torch.get_num_threads()}
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}

    def fill(tmp: Path) -> None:
        torch.save({"state_dict": state, "args": args}, tmp / "model.tar")
        write_json(tmp / "args.json", args)
        write_json(tmp / "metrics.json", metrics)
        write_json(tmp / COMPLETE, {"files": ["model.tar", "args.json", "metrics.json"]})

    atomic_folder(directory, fill)
    return directory


def load_run(directory) -> tuple[torch.nn.Module, dict, dict]:
    """``(model in eval mode, args, metrics)`` of a saved run."""
    directory = Path(directory)
    ckpt = directory / "model.tar"
    if not ckpt.exists():
        raise FileNotFoundError(f"no checkpoint at {ckpt}; train it first (see the task's train.py)")
    if not _is_complete(directory):
        raise RuntimeError(f"run folder {directory} lacks {COMPLETE} or a file it lists: its save was interrupted "
                           "(or it predates whole-folder saves); delete the run folder and retrain")
    try:
        blob = torch.load(ckpt, map_location="cpu", weights_only=True)
    except Exception as err:
        raise RuntimeError(f"checkpoint {ckpt} is unreadable ({err}); delete the run folder and retrain") from err
    model = model_from_args(blob["args"])
    model.load_state_dict(blob["state_dict"])
    metrics_path = directory / "metrics.json"
    metrics = json.loads(metrics_path.read_text()) if metrics_path.exists() else {}
    return model.eval(), blob["args"], metrics
