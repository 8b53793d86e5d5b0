"""Grouped training as runs: configs that ``unit_key`` puts together trained as one program
(``hnn.trainers.closed_form`` for the paper's tanh-MLP kinds, ``hnn.trainers.vmap`` for every
other) and saved each as its own ordinary run folder, as ``hnn.run_experiment`` saves a lone run.

    folders = hnn.sweeps.group_runs.train_group([SpringConfig(seed=s, hidden_dim=32) for s in range(4)])

``run_group_task`` is the same for a sweep's worker process or Ray task (plain data in and out).
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path

import torch

from ..errors import DivergenceError
from ..kinds import get_kind
from ..objectives import DerivativeObjective
from ..policy import prepare
from ..runs import COMPLETE, finish_run, record_divergence, run_dir, run_experiment
from ..specs import run_specs
from ..tasks import task_config
from ..threads import torch_threads
from ..trainers import closed_form, vmap


# the fields that must agree for configs to train as one program (seed, train_fraction and with
# them the dataset may differ)
_SHARED_FIELDS = ("input_dim", "hidden_dim", "learn_rate", "weight_decay", "batch_size", "total_steps",
                  "print_every", "field_type", "dtype", "device")


def closed_form_key(config) -> tuple | None:
    """Configs with equal keys can train as one closed-form group (``hnn.trainers.closed_form``); None for a config that trains alone
    (another kind, ``use_rk4``, another nonlinearity than tanh, an objective of its own, or an
    optimizer, schedule, gradient clipping or derivative loss other than the paper's constant-rate
    Adam on the squared error, or ``balance='rms'``)."""
    if (get_kind(config.kind).grouping != "closed_form" or config.use_rk4 or config.nonlinearity != "tanh" or config.balance == "rms"
            or (config.optimizer, config.schedule, config.clip_grad, config.derivative_loss)
            != ("adam", "constant", 0.0, "l2")
            or type(config.make_objective()) is not DerivativeObjective):
        return None
    return ((type(config).__module__, type(config).__qualname__, config.kind, run_specs(config).objective.input_noise)
            + tuple(getattr(config, name) for name in _SHARED_FIELDS))


# the fields that may differ within a stacked group: each model's seed, data fraction and init
_OWN_FIELDS = ("seed", "train_fraction", "init")


def vmap_key(config) -> tuple | None:
    """Configs with equal keys can train as one stacked group (``hnn.trainers.vmap.train_vmap``); None for a config that
    ``closed_form_key`` groups (its closed form is faster) or that trains alone: the pixel kinds
    (their objective draws noise of its own). The key is the run's identity less ``_OWN_FIELDS``, and
    the facts its model is built from (the chain's constraints)."""
    if closed_form_key(config) is not None or get_kind(config.kind).grouping == "alone":
        return None
    same = {k: v for k, v in config.identity().items() if k not in _OWN_FIELDS}
    return (type(config).__module__, type(config).__qualname__,      # the identity's JSON: a hashable key
            json.dumps({**same, **config.model_facts()}, sort_keys=True, default=str))


def unit_key(config) -> tuple | None:
    """Configs with equal keys train as one group: ``("closed_form", ...)`` for the paper's tanh-MLP kinds
    (``hnn.trainers.closed_form``), ``("vmap", ...)`` for any other kind (``hnn.trainers.vmap``),
    None for a config that trains alone (the pixel kinds)."""
    specs = run_specs(config)
    if specs.objective.units == "on":     # a rescaled run trains its own canonical data alone
        return None
    if specs.fit.fit != "adam":            # a least-squares fit is one solve, no loop to share
        return None
    key = closed_form_key(config)
    if key is not None:
        return ("closed_form",) + key
    key = vmap_key(config)
    return None if key is None else ("vmap",) + key


def group_checkpoint(configs: list) -> Path:
    """The training checkpoint of the group of ``configs`` while it trains (``hnn.trainers.group_loop.GroupCheckpoint``):
    ``<save_dir>/.group-<hash>.partial.pt``, the hash of its runs' folder names, so the same group started
    again finds it and another group does not."""
    names = "\n".join(run_dir(config).name for config in configs)
    return Path(configs[0].save_dir) / f".group-{hashlib.sha1(names.encode()).hexdigest()[:12]}.partial.pt"


def drop_spent_checkpoints(save_dir) -> list[Path]:
    """Delete the group checkpoints in ``save_dir`` (``group_checkpoint``'s files) whose members' runs are all
    saved by now: a group killed mid-way whose runs a later sweep trained in other groups or alone, which no
    rerun forms again. A checkpoint that cannot be read, or that does not name its members, is left. Returns
    the files deleted."""
    dropped = []
    for path in sorted(Path(save_dir).glob(".group-*.partial.pt")):
        try:
            names = torch.load(path, map_location="cpu", weights_only=True)["stats"]["names"]
        except Exception:       # being written, corrupt or of an older hnn: not this function's to judge
            continue
        if names and all((path.parent / name / COMPLETE).is_file() for name in names):
            path.unlink(missing_ok=True)
            dropped.append(path)
    return dropped


def train_group(configs: list, datasets: list[dict] | None = None) -> list:
    """Train ``configs`` (equal ``unit_key``s) as one group and save each as its own run folder
    (as ``hnn.run_experiment`` would); per config its folder, or the ``GroupedRunFailed`` of a
    model that failed. ``datasets``: each config's dataset (default ``config.dataset()``). While it
    trains the group keeps a checkpoint (``group_checkpoint``) that the same group resumes from after a
    kill; it is deleted once the runs are saved, when the group fails, or with a config's ``force``."""
    keys = {unit_key(config) for config in configs}
    if None in keys or len(keys) != 1:
        raise ValueError("train_group needs configs of one group (equal hnn.sweeps.group_runs.unit_key, none None); "
                         "train the others alone with hnn.run_experiment")
    objective = configs[0].make_objective()
    # each member prepared as its lone run is (its checks, save_dir, init, units, balance and rows: hnn.policy.prepare)
    preps = [prepare(config, dataset, objective, saves=True)
             for config, dataset in zip(configs, datasets or [config.dataset() for config in configs])]
    if any(p.scales is not None or p.options.loss_weights is not None for p in preps):
        # --units or --balance resolved to what a group's program does not do: each trains alone
        return [_alone(p.config, p.dataset) for p in preps]
    partial = group_checkpoint(configs)
    if any(config.force for config in configs):
        partial.unlink(missing_ok=True)
    trainer = closed_form if next(iter(keys))[0] == "closed_form" else vmap
    try:
        stats, failures = trainer.train_prepared(preps, checkpoint=partial, names=[run_dir(c).name for c in configs])
    except Exception:       # a failure repeats from the checkpoint; an interrupt (not an Exception) keeps it
        partial.unlink(missing_ok=True)
        raise
    out = []
    for g, prep in enumerate(preps):
        # a failed model's failure, else its run saved with its own options' numbers
        out.append(failures[g] if g in failures else finish_run(prep, stats[g]))
    partial.unlink(missing_ok=True)
    drop_spent_checkpoints(configs[0].save_dir)        # an older group of these runs, killed mid-way
    return out


def _alone(config, dataset):
    """``config`` trained alone (``hnn.run_experiment``): its folder, or the DivergenceError of a failed run."""
    try:
        return run_experiment(config, dataset)
    except DivergenceError as err:
        return err


def run_group_task(task: str, values: list[Mapping], threads: int | None = None) -> list[dict]:
    """A sweep's group in a worker process or a Ray task: the configs of ``task`` with ``values``
    trained as one group (``threads`` sets torch's thread count first). Per config
    ``{"folder": text}`` or ``{"error": message, "diverged": whether the model itself failed}`` (plain data:
    it crosses process boundaries)."""
    configs = [task_config(task, v) for v in values]
    try:
        with torch_threads(threads):        # the caller's count comes back afterwards
            outcomes = train_group(configs)
    except DivergenceError as err:
        outcomes = [err] * len(configs)
        _record_diverged(configs, outcomes)
        raise
    _record_diverged(configs, outcomes)
    return [{"error": str(o), "diverged": isinstance(o, DivergenceError)} if isinstance(o, Exception)
            else {"folder": str(o)} for o in outcomes]


def _record_diverged(configs: list, outcomes: list) -> None:
    """Each model that failed in training recorded as it fails (``hnn.runs.record_divergence``), as a lone
    run's worker does (``hnn.tasks.run_task``): the sweep that reads these outcomes may be stopped first."""
    for config, outcome in zip(configs, outcomes):
        if isinstance(outcome, DivergenceError):
            record_divergence(config, outcome)


__all__ = ["drop_spent_checkpoints", "group_checkpoint", "closed_form_key", "run_group_task", "vmap_key", "train_group",
           "unit_key"]
