"""What ``analysis/reproduce.py`` does with each task after training: the per-task registry.

Training is the same for every task (its ``experiment-<task>/train.py``, with ``--save_dir``,
``--seed``, ``--baseline`` and ``--total_steps``). Evaluation and figures differ, so each task
has a ``TaskHooks`` entry in ``HOOKS``; a task without one (a new task)
gets ``DEFAULT``: the energy MSE under its protocols in ``hnn.PROTOCOLS`` (none if it has
none) and one energy-over-time figure per protocol. To plug a task in, add::

    HOOKS["mytask"] = TaskHooks(evaluate=my_evaluate, figures=my_figures, cost=20.0)

with

- ``evaluate(task: str, system, models: dict) -> dict[str, dict]``: ``{protocol name: result}``,
  where ``result`` is like ``hnn.evaluate_energy``'s (``result[label]["mse"]`` and
  ``["mse_se"]`` for each label of ``models``) plus ``"description"`` (one line of text). The
  protocol named ``"paper"`` is compared with the paper's number; others are shown beside it.
- ``figures(task: str, system, models: dict, energy: dict, fig_dir: Path) -> dict``: writes its
  files into ``fig_dir`` (atomically) and returns numbers worth keeping in ``results.json``
  (``{}`` if none). ``energy`` is what ``evaluate`` returned.
- ``load(directory) -> (model, args, metrics)``: reads one saved run (default ``hnn.load_run``).
- ``cost``: the relative wall time of one full training run, so ``--jobs N`` starts the longest first.
- ``quick_argv``: extra ``train.py`` flags for ``--quick`` (e.g. a smaller dataset).
- ``train_argv``: extra ``train.py`` flags for every run.
- ``variants``: extra rows beside the paper's setting, ``{suffix: (train.py flags, why)}``; the
  row ``<task>-<suffix>`` trains with those flags under ``--name <task>-<suffix>`` and is
  shown below the paper's rows with its reason.

``system`` is the task's data module (``hnn.load_task(task)``) and ``models`` is
``{"baseline": model, "hnn": model}``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

import hnn
from hnn_analysis import figures, mischief, orbit_figures, pixel_figures


def energy_protocols(task: str, system, models: dict) -> dict:
    """Every protocol of ``hnn.PROTOCOLS[task]`` run on ``models``; ``{}`` for a task with none."""
    protocols = [hnn.get_protocol(task, name) for name in hnn.PROTOCOLS.get(task, {})]
    # only the real pendulum's protocols need the dataset (its measured test segment)
    dataset = system.get_dataset() if any(p.x0 == "test_segment" for p in protocols) else None
    out = {}
    for protocol in protocols:
        result = hnn.evaluate_energy(system, models, protocol, dataset)
        result["description"] = protocol.describe()
        out[protocol.name] = result
    return out


def energy_figures(task: str, system, models: dict, energy: dict, fig_dir: Path) -> dict:
    """``<task>-energy-<protocol>.png``: energy over time for every trial of every protocol."""
    for name, result in energy.items():
        figures.energy_figure(task, result, fig_dir / f"{task}-energy-{name}.png")
    return {}


def phase_plane_figures(task: str, system, models: dict, energy: dict, fig_dir: Path) -> dict:
    """The 1-DOF toy tasks (spring, pend): fields, integration, energy, energy bump, reversibility."""
    energy_figures(task, system, models, energy, fig_dir)
    figures.field_figure(task, system, models, system.get_dataset(seed=0), fig_dir / f"{task}-fields.png")
    figures.integration_figure(task, system, models, fig_dir / f"{task}-integration.png")
    x0 = figures.FIELD_SETTINGS[task]["x0"]
    return mischief.mischief_figures(task, system, models, x0, fig_dir)


def real_figures(task: str, system, models: dict, energy: dict, fig_dir: Path) -> dict:
    """The real pendulum: measured data, learned fields, energy along the test segment, mischief."""
    energy_figures(task, system, models, energy, fig_dir)
    dataset = system.get_dataset()
    figures.real_figure(task, models, dataset, energy.get("paper"), fig_dir / f"{task}-fields.png")
    x0 = tuple(float(v) for v in np.asarray(dataset["test_x"], dtype=np.float64)[0])
    return mischief.mischief_figures(task, system, models, x0, fig_dir)


def nbody_figures(task: str, system, models: dict, energy: dict, fig_dir: Path) -> dict:
    """The orbit tasks: orbits of truth / baseline / HNN from the protocol's seed-0 state, and a GIF."""
    energy_figures(task, system, models, energy, fig_dir)
    result = energy["paper"]
    orbit_figures.orbit_figure(task, result, fig_dir / f"{task}-orbits.png")
    orbit_figures.orbit_gif(task, result, fig_dir / f"{task}-orbits.gif")
    return {}


@dataclass(frozen=True)
class TaskHooks:
    evaluate: Callable[[str, object, dict], dict] = energy_protocols
    figures: Callable[[str, object, dict, dict, Path], dict] = energy_figures
    load: Callable = hnn.load_run
    cost: float = 1.0
    quick_argv: tuple[str, ...] = field(default_factory=tuple)
    train_argv: tuple[str, ...] = field(default_factory=tuple)
    variants: dict = field(default_factory=dict)


DEFAULT = TaskHooks()

# the paper's orbit datasets keep every orbit (--min_separation 0, the tasks' default); this row
# shows what redrawing the close encounters changes (3-body only: no 2-body orbit comes that
# close, so its cleaned dataset is the same rows)
CLEAN_ORBITS = {"clean": (("--min_separation", str(hnn.nbody.MIN_SEPARATION)),
                          f"the cleaned dataset (--min_separation {hnn.nbody.MIN_SEPARATION:g}): orbits whose bodies "
                          "come closer than that are redrawn, since near-collisions give huge, badly integrated "
                          "dx/dt that dominate the squared loss (about 3% of the 3-body orbits); not the "
                          "paper's setting")}

# cost: measured full-settings training time of one model, in seconds on 2 cores (rounded)
HOOKS = {
    "spring": TaskHooks(figures=phase_plane_figures, cost=12),
    "pend": TaskHooks(figures=phase_plane_figures, cost=12),
    "real": TaskHooks(figures=real_figures, cost=8),
    "2body": TaskHooks(figures=nbody_figures, cost=60),
    "3body": TaskHooks(figures=nbody_figures, cost=90, variants=CLEAN_ORBITS),
    # train.py's own evaluation is skipped: reproduce evaluates both models together; --quick
    # renders 50 trajectories instead of 200
    "pixels": TaskHooks(evaluate=pixel_figures.pixel_energy, figures=pixel_figures.pixel_figures,
                        load=pixel_figures.load_run, cost=250, quick_argv=("--trials", "50"),
                        train_argv=("--no_eval",)),
}


def hooks_for(task: str) -> TaskHooks:
    """The task's hooks, or ``DEFAULT`` for a task without an entry."""
    return HOOKS.get(task, DEFAULT)

