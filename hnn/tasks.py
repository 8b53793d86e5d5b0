"""The tasks of this checkout, found by folder: the one place where the package knows the repo layout.

Task ``name`` is the folder ``<repo>/experiment-<name>/`` holding a ``data.py`` (the system: H,
true dynamics, sampler, ``get_dataset``), a ``train.py`` (``Config``, its ``hnn.RunConfig``
subclass: fields, defaults and ``dataset()``; ``main`` parses the flags into one and runs it) and, optionally, a ``task.py`` that describes it with one object,
``TASK = hnn.TaskSpec(...)``: its place in the paper's order, energy protocols, published
numbers, figures, training cost and extra rows. A new task is one new folder; the package lists
no task names. Folder names have hyphens, so the modules are loaded by path, each under a
unique module name.

    hnn.available_tasks()            # e.g. ['spring', 'pend', ...]: every folder, in TaskSpec.order
    hnn.tasks.task_names()           # the same folders by name, without loading a spec (torch-free)
    hnn.task_spec("spring").cost     # its task.py's TASK (a default TaskSpec without one)
    hnn.PROTOCOLS["spring"]["paper"] # read-only views built from the specs when read
"""
from __future__ import annotations

import importlib
import importlib.util
import math
import os
import sys
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Protocol

from .errors import DivergenceError

_PREFIX = "experiment-"


@dataclass(frozen=True)
class TaskSpec:
    """What a task says about itself in ``experiment-<name>/task.py`` (``TASK = hnn.TaskSpec(...)``).

    Attributes:
        order: its place in the paper's order; tasks are listed by ``(order, name)``.
        protocols: ``{name: protocol}``, its energy protocols (``hnn.EnergyProtocol`` unless it
            has its own ``evaluate``); the one named ``'paper'`` is compared with the paper's number.
        paper: the published numbers, ``{metric: {model: (mean, ±)}}`` for ``train_loss``,
            ``test_loss`` and ``energy_mse``.
        figures: names in the analysis package's figure registry (``hnn_analysis.paper.registry.FIGURES``),
            drawn in this order by ``analysis/reproduce.py``.
        figure_settings: what those figures need from the task, ``{figure name: {setting: value}}``
            plus shared keys (``x0``, the start state of the phase-plane figures).
        cost: relative wall time of one full training run (``--jobs N`` starts the longest first).
        data_cost: seconds of one build of its dataset at its ``quick`` settings on the quick budgets' reference
            box (``hnn_analysis.plan``, a quiet 2-core box): a quick mode's plan prices its builds by it.
        evaluate_cost: seconds of its ``reproduce.py --quick`` evaluation of a row on that reference box: the
            paper's pair under every energy protocol at the quick trials, and the row's figures.
        quick: config fields for ``reproduce.py --quick``, ``{field: value}`` (e.g. a smaller dataset).
        settings: config fields for every run of ``reproduce.py`` and the sweeps.
        variants: extra table rows, ``{suffix: ({field: value}, why)}``: row ``<task>-<suffix>``
            trains with those fields under the name ``<task>-<suffix>``, shown with its reason.
        evaluate: ``evaluate(trained) -> {protocol name: result}`` replacing the default (every
            protocol through ``hnn.evaluate_energy``); ``trained`` has ``task``, ``system``,
            ``models`` (``{label: model}``), ``args`` (the runs' saved args) and ``dataset`` (the
            dataset rebuilt from them); each result has ``result[label]["mse"]`` and ``["mse_se"]``
            and a one-line ``"description"``.
        load: ``load(directory) -> (model, args, metrics)`` replacing ``hnn.load_run``.
        in_paper: one of the paper's tasks (``paper_tasks``); False keeps a task out of
            ``analysis/reproduce.py``'s default tasks and tables (it still trains and loads).
        min_seeds: a reproduction across seeds (``--seeds`` of 2 or more) trains at least this many
            seeds of the task, for a task whose numbers vary widely from seed to seed.
        scene_study: the scene study's settings (``analysis/scene_study.py``); None: not one of its
            scenes. ``T`` (the training trajectories' length, scene time; absent: no rollout
            metrics), ``dts`` (the speed ladder's fixed steps), ``period``, ``periods``, ``unit``
            (the long drift run: the period, None to measure it per start, how many, their name),
            ``grid`` (train the width x data grid), ``drift`` (run the long drift).
        integrator_study: the integrator study's settings (``analysis/integrator_study/speed_accuracy.py``);
            None for a task without true dynamics to measure against. ``T`` (the horizon), ``dts``
            (fixed steps), ``batch`` (start states), ``model_time`` (the models' time units per
            scene time unit, default 1), ``quick`` (studied by ``--quick`` too).
    """
    order: float = math.inf
    protocols: Mapping = field(default_factory=dict)
    paper: Mapping = field(default_factory=dict)
    figures: tuple[str, ...] = ("energy",)
    figure_settings: Mapping = field(default_factory=dict)
    cost: float = 1.0
    data_cost: float = 1.0
    evaluate_cost: float = 5.0
    quick: Mapping = field(default_factory=dict)
    settings: Mapping = field(default_factory=dict)
    variants: Mapping = field(default_factory=dict)
    evaluate: Callable | None = None
    load: Callable | None = None
    in_paper: bool = True
    min_seeds: int = 1
    scene_study: Mapping | None = None
    integrator_study: Mapping | None = None


def repo_root() -> Path:
    """The checkout that holds the ``experiment-*`` folders (``HNN_REPO`` overrides)."""
    root = Path(os.environ.get("HNN_REPO", Path(__file__).resolve().parent.parent))
    if not any(root.glob(f"{_PREFIX}*")):
        raise FileNotFoundError(
            f"no experiment-* folders under {root}: the tasks live in the repository, not in the "
            "installed package; install it with `pip install -e .` from a checkout, or set HNN_REPO")
    return root


def _has_task(name: str) -> bool:
    return (repo_root() / f"{_PREFIX}{name}" / "data.py").is_file()


def task_names() -> list[str]:
    """The task folders of this checkout by name, sorted by name, without reading their specs (which loads
    torch): what a command checks its input against before anything heavy loads."""
    return sorted(p.parent.name[len(_PREFIX):] for p in repo_root().glob(f"{_PREFIX}*/data.py"))


def available_tasks() -> list[str]:
    """Names of the tasks in this checkout (every ``experiment-<name>/`` with a ``data.py``),
    in the paper's order (``TaskSpec.order``, then the name)."""
    names = [p.parent.name[len(_PREFIX):] for p in repo_root().glob(f"{_PREFIX}*/data.py")]
    return sorted(names, key=lambda name: (task_spec(name).order, name))


def paper_tasks() -> list[str]:
    """The ``available_tasks`` that are the paper's (``TaskSpec.in_paper``), in its order."""
    return [name for name in available_tasks() if task_spec(name).in_paper]


def task_spec(name: str) -> TaskSpec:
    """The ``TASK`` of ``experiment-<name>/task.py``; a default ``TaskSpec`` (no protocols, no
    paper numbers, energy figures only) for a task folder without one."""
    if not _has_task(name):
        raise ValueError(f"unknown task {name!r} (no {repo_root() / (_PREFIX + name) / 'data.py'}); "
                         f"available: {available_tasks()}")
    if not (repo_root() / f"{_PREFIX}{name}" / "task.py").is_file():
        return TaskSpec()
    spec = getattr(load_task(name, "task"), "TASK", None)
    if not isinstance(spec, TaskSpec):
        raise TypeError(f"experiment-{name}/task.py must define TASK = hnn.TaskSpec(...), got {spec!r}")
    return spec


class _FromSpecs(Mapping):
    """A read-only ``{task: spec.<attribute>}`` over the tasks whose attribute is not empty,
    read from the task folders whenever it is used (so it follows ``HNN_REPO``)."""

    def __init__(self, attribute: str):
        self._attribute = attribute

    def _value(self, task: str) -> Mapping:
        return getattr(task_spec(task), self._attribute) if _has_task(task) else {}

    def __getitem__(self, task: str) -> Mapping:
        value = self._value(task) if isinstance(task, str) else {}
        if not value:
            raise KeyError(task)
        return MappingProxyType(dict(value))

    def __iter__(self):
        return iter([task for task in available_tasks() if self._value(task)])

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def __repr__(self) -> str:
        return f"{{{', '.join(f'{task!r}: {dict(self[task])!r}' for task in self)}}}"


# task -> name -> protocol: the specs' protocols
PROTOCOLS = _FromSpecs("protocols")
# the published numbers (the original README, one run each at seed 0), the specs' ``paper``:
# PAPER[task][metric][model] -> (mean, ±), metric train_loss, test_loss or energy_mse, model baseline or
# hnn; the paper's Table 1 shows them scaled (x10^3; 2-body x10^6; pixel losses x10^5; Table 2, 3-body,
# x10^2); docs/original.md says how each was measured
PAPER = _FromSpecs("paper")


def get_protocol(task: str, name: str = "paper"):
    """Protocol ``name`` of ``task`` (an ``hnn.EnergyProtocol``), as its ``task.py`` declares it
    (``hnn.PROTOCOLS[task][name]``); a ValueError naming the protocols there are."""
    try:
        return PROTOCOLS[task][name]
    except KeyError:
        raise ValueError(f"no energy protocol {name!r} for task {task!r}; have "
                         f"{ {t: sorted(p) for t, p in PROTOCOLS.items()} }") from None


def task_config(task: str, values: Mapping | None = None):
    """The config of a run of ``task`` (its ``train.py``'s ``Config``) with ``values`` over the
    defaults; a saved run's args.json gives that run's config (its recorded keys aside)."""
    trainer = load_task(task, "train")
    if not hasattr(trainer, "Config"):
        raise AttributeError(f"experiment-{task}/train.py has no Config: add its hnn.RunConfig subclass")
    return trainer.Config.from_dict(dict(values or {}))


def run_dataset(task: str, args: Mapping) -> dict:
    """The dataset a saved run of ``task`` trained on: its config's ``dataset()`` from the run's
    saved ``args`` (so evaluation sees that run's seed, files and sizes, not the defaults).
    Warns when the run recorded another cache file than the one the dataset now comes from."""
    data = task_config(task, args).dataset()
    recorded = args.get("dataset_cache_key")
    if recorded and data.get("cache_key") != recorded:
        warnings.warn(f"{task}: the run trained on the cached dataset {recorded}, but its args now give "
                      f"{data.get('cache_key')} (was the dataset generator changed?)", stacklevel=2)
    return data


def run_task(task: str, values: Mapping, threads: int | None = None, on_step=None) -> str:
    """Train the run of ``task`` with config ``values`` (a sweep's job, in a worker process or a Ray
    task; ``threads`` sets torch's thread count first; ``on_step``: ``hnn.run_experiment``'s); returns its
    folder as text."""
    from .runs import record_divergence, run_experiment     # here: finding and reading tasks loads no torch
    from .threads import torch_threads

    config = task_config(task, values)
    # the caller's thread count comes back afterwards: a library call leaves no global setting changed
    with torch_threads(threads):
        try:
            return str(run_experiment(config, on_step=on_step))
        except DivergenceError as err:
            # recorded here, as it fails: the sweep that reads this outcome may be busy with another's (its
            # on_done) or stopped before it does
            record_divergence(config, err)
            raise


def _load(mod_name: str, path: Path, package: Path | None = None) -> ModuleType:
    """The file ``path`` executed as module ``mod_name`` (a package searching ``package`` if given)."""
    locations = None if package is None else [str(package)]
    spec = importlib.util.spec_from_file_location(mod_name, path, submodule_search_locations=locations)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = mod
    try:
        spec.loader.exec_module(mod)
    except BaseException:
        del sys.modules[mod_name]
        raise
    return mod


class TaskData(Protocol):
    """What a task's ``data.py`` offers (``load_task(name)``), checked when it loads (``check_task_data``).

    - ``get_dataset(**fields) -> dict``: always; its config's ``dataset()`` calls it.
    - ``hamiltonian(x)`` ``(batch, dim) -> (batch,)``: where the task declares an energy protocol
      (``TaskSpec.protocols``): the energy the protocol scores.
    - ``dynamics(x)`` ``(batch, dim) -> (batch, dim)``: where a protocol integrates the truth from
      starts it draws (``x0`` ``'box'`` or ``'seeds'``; a measured segment needs none).

    Read where present: ``initial_state`` (the orbits' own starts: the integrator study draws its trials
    from it), ``sample_starts`` and ``true_hamiltonian`` (the pixel task's simulator starts and energy),
    ``RADIUS_RANGE`` and ``NOISE_STD`` (the toy tasks' data ranges, the studies' starts and noise)."""

    def get_dataset(self, **fields) -> dict: ...


def check_task_data(name: str, data: ModuleType) -> None:
    """TypeError naming what ``experiment-<name>/data.py`` lacks of ``TaskData`` for its declared protocols."""
    needs = {"get_dataset": "its config's dataset() calls it"}
    for protocol in task_spec(name).protocols.values():
        needs.setdefault("hamiltonian", f"its energy protocol {protocol.name!r} scores it")
        if getattr(protocol, "x0", None) in ("box", "seeds"):     # a task's own protocol class may draw none
            needs.setdefault("dynamics", f"its protocol {protocol.name!r} integrates the truth with it")
    missing = [f"{attr} ({why})" for attr, why in needs.items() if not callable(getattr(data, attr, None))]
    if missing:
        raise TypeError(f"experiment-{name}/data.py lacks {', '.join(missing)}: define it there "
                        "(hnn.tasks.TaskData says what a task's data module offers)")


def load_task(name: str, module: str = "data") -> ModuleType:
    """``experiment-<name>/<module>.py`` as a module (cached, so each is loaded once); a ``data.py`` is
    checked against ``TaskData`` when it loads."""
    path = repo_root() / f"{_PREFIX}{name}" / f"{module}.py"
    if not path.exists():
        raise ValueError(f"unknown task {name!r} (no {path}); available: {available_tasks()}")
    mod_name = f"hnn_task_{name}_{module}"
    cached = sys.modules.get(mod_name)
    if cached is not None and getattr(cached, "__file__", None) == str(path):
        return cached
    loaded = _load(mod_name, path)      # first use, or a task of that name in another checkout (HNN_REPO)
    if module == "data":
        try:
            check_task_data(name, loaded)
        except TypeError:
            del sys.modules[mod_name]
            raise
    return loaded
