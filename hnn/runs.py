"""A run: train one model from its config (``hnn.RunConfig``: settled by ``hnn.policy.prepare``, its weights
found by ``hnn.trainers.lone``), and save / load it.

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

import json
from pathlib import Path
from typing import Callable

import torch

from .io import atomic_folder, torch_bytes, write_json
from .kinds import model_from_args
from .objectives import Objective
from .policy import Prepared, prepare, seeded
from .trainers.lone import find_weights


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


def run_experiment(config, dataset=None, objective: Objective | None = None,
                   on_step: Callable[[int, int], None] | None = None) -> Path:
    """Train the model that ``config`` (an ``hnn.RunConfig``) describes and save the run; returns
    its folder. Every task and model kind trains here, in three stages: ``hnn.policy.prepare(config, dataset,
    objective)`` settles the run (its arguments: ``prepare``'s), ``hnn.trainers.lone.find_weights`` finds its
    weights (``on_step(done, total)`` after each step of its loop: a sweep's bar, or a study that stops a run
    by raising) and ``finish_run`` scores and saves it; a ``dataset`` given as a function has its time saved
    as ``data_seconds`` in ``metrics.json`` beside ``train_seconds`` (the training loop alone).
    """
    prep = prepare(config, dataset, objective, saves=True)
    partial = partial_checkpoint(config)
    if config.force:
        partial.unlink(missing_ok=True)
    try:
        stats = find_weights(prep, checkpoint=partial, on_step=on_step)
    except Exception:       # a failure repeats from the checkpoint; an interrupt (not an Exception) keeps it
        partial.unlink(missing_ok=True)
        raise
    return finish_run(prep, stats, spent=partial)


def finish_run(prep: Prepared, stats: dict, spent: Path | None = None) -> Path:
    """Score, print (with ``verbose``) and save the trained run ``prep`` (``hnn.policy.Prepared``) as its folder
    (``run_dir``): its final ``(mean, ±)`` train and test losses in the user's units (``Prepared.final_losses``),
    the seconds of its data and of its loop, and the loss history ``stats``; then deletes ``spent`` (its
    training checkpoint, if any) and runs the config's own ``finish`` (a pixel run's rollout and GIFs).
    Returns the folder."""
    config = prep.config
    train_loss, test_loss = prep.final_losses()
    if config.verbose:
        print(f"Final train loss {train_loss[0]:.4e} +/- {train_loss[1]:.4e}\n"
              f"Final test loss {test_loss[0]:.4e} +/- {test_loss[1]:.4e}")
    metrics = {"train_loss": train_loss[0], "train_loss_se": train_loss[1],
               "test_loss": test_loss[0], "test_loss_se": test_loss[1],
               "data_seconds": prep.data_seconds, "train_seconds": stats["seconds"], "history": stats}
    directory = save_run(run_dir(config), prep.model, prep.saved, metrics)
    if spent is not None:
        spent.unlink(missing_ok=True)
    config.finish(directory, prep.dataset)
    return directory


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
    recorded device is where it trained, not where it must be read: a GPU's run loads on a CPU); the caller's
    random state is left as it was."""
    directory = Path(directory)
    ckpt = directory / "model.tar"
    if not ckpt.exists():
        raise FileNotFoundError(f"no checkpoint at {ckpt}; train it first (see the task's train.py)")
    if not is_complete(directory):
        raise RuntimeError(f"run folder {directory} lacks {COMPLETE} or a file it lists: its save was interrupted "
                           "; delete the folder and retrain")
    try:
        blob = torch.load(ckpt, map_location="cpu", weights_only=True)
        with seeded(0):     # its init's draws, replaced by the saved weights, leave the caller's random state be
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
