"""What ``reproduce.py`` does with a task after training: its evaluation, and its figures by name.

A task's ``task.py`` names its figures (``TaskSpec.figures``); ``FIGURES`` maps each name to
the function that draws it, ``draw(trained, energy, fig_dir) -> dict``: it writes its files
into ``fig_dir`` (atomically) and returns numbers worth keeping in ``results.json`` (``{}`` if
none). ``trained`` is a ``Trained`` (the task, its data module, ``{"baseline": model, "hnn":
model}``, the runs' saved args and the dataset rebuilt from them); ``energy`` is what the
task's evaluation returned, ``{protocol name: result}``. A new figure is one function here and
its name in a task's ``figures``.

    trained = Trained("spring", hnn.load_task("spring"), models, args)
    energy = evaluate(trained)                        # the task's evaluate, or every energy protocol
    numbers = draw_figures(trained, energy, fig_dir)  # every figure the task names
"""
from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np

import hnn
from hnn_analysis.paper import figures, mischief, orbit_figures, pixel_figures


@dataclass
class Trained:
    """A task's trained models with the saved args they were trained with."""
    task: str
    system: ModuleType
    models: dict
    args: dict

    @property
    def spec(self) -> hnn.TaskSpec:
        return hnn.task_spec(self.task)

    @functools.cached_property
    def dataset(self) -> dict:
        """The dataset the runs trained on, rebuilt from their saved args (once, when first used)."""
        return hnn.tasks.run_dataset(self.task, self.args)


def energy_protocols(trained: Trained, num_trials: int | None = None) -> dict:
    """Every protocol of the task's ``task.py`` through ``hnn.evaluate_energy``; ``{}`` for a task with
    none. ``num_trials``: that many trials of each protocol that starts several (a ``--quick`` run's)."""
    protocols = [p if num_trials is None or p.x0 == "test_segment" else dataclasses.replace(p, num_trials=num_trials)
                 for p in trained.spec.protocols.values()]
    # only the real pendulum's protocols need the dataset (its measured test segment)
    dataset = trained.dataset if any(p.x0 == "test_segment" for p in protocols) else None
    out = {}
    for protocol in protocols:
        result = hnn.evaluate_energy(trained.system, trained.models, protocol, dataset,
                                     observed=(dataset or {}).get("state", "canonical"))
        result["description"] = protocol.describe()
        out[protocol.name] = result
    return out


def evaluate(trained: Trained, num_trials: int | None = None) -> dict:
    """``{protocol name: result}``: the task's own ``evaluate``, or ``energy_protocols`` (of
    ``num_trials`` trials each when given)."""
    if trained.spec.evaluate is not None:
        return trained.spec.evaluate(trained)
    return energy_protocols(trained, num_trials)


def evaluate_seeds(seeds: list[Trained], num_trials: int | None = None) -> list[dict]:
    """``evaluate`` of each of a task's seeds (the same kinds in each), with each protocol's models
    scored as groups: one ``hnn.evaluate_energy`` call per protocol holds every seed's model of a kind
    (the truth integrated once; a ``row_wise`` method steps a group's trials in one integration). A
    task with its own ``evaluate``, and a protocol on the measured test segment (its truth is the
    data a seed's args rebuild), go seed by seed. Each seed's result equals its ``evaluate``'s."""
    spec = seeds[0].spec
    if spec.evaluate is not None or len(seeds) == 1:
        return [evaluate(trained, num_trials) for trained in seeds]
    out = [{} for _ in seeds]
    kinds = list(seeds[0].models)
    for protocol in spec.protocols.values():
        if protocol.x0 == "test_segment":
            for trained, energy in zip(seeds, out):
                dataset = trained.dataset
                energy[protocol.name] = hnn.evaluate_energy(trained.system, trained.models, protocol, dataset,
                                                            observed=dataset.get("state", "canonical"))
        else:
            if num_trials is not None:
                protocol = dataclasses.replace(protocol, num_trials=num_trials)
            group = hnn.evaluate_energy(seeds[0].system, {k: [t.models[k] for t in seeds] for k in kinds}, protocol)
            shared = {key: value for key, value in group.items() if key not in kinds}
            for i, energy in enumerate(out):
                energy[protocol.name] = {**shared, **{k: group[k][i] for k in kinds}}
        for energy in out:
            energy[protocol.name]["description"] = protocol.describe()
    return out


# ----------------------------------------------------------------------------------------------
# the figures


def _energy(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-energy-<protocol>.png``: energy over time for every trial of every protocol."""
    for name, result in energy.items():
        figures.energy_figure(trained.task, result, fig_dir / f"{trained.task}-energy-{name}.png")
    return {}


def _fields(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-fields.png``: the data, the true field and each model's, with a trajectory each."""
    figures.field_figure(trained.task, trained.system, trained.models, trained.dataset,
                         fig_dir / f"{trained.task}-fields.png")
    return {}


def _integration(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-integration.png``: one rollout of truth and models, their errors and energies."""
    figures.integration_figure(trained.task, trained.system, trained.models, fig_dir / f"{trained.task}-integration.png")
    return {}


def _real_fields(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-fields.png`` of a task with no true field: measurements, learned fields, energy."""
    figures.real_figure(trained.task, trained.models, trained.dataset, energy.get("paper"),
                        fig_dir / f"{trained.task}-fields.png")
    return {}


def _start(trained: Trained) -> tuple[float, ...]:
    """The phase-plane figures' start: the task's ``figure_settings["x0"]``, else the first test state."""
    x0 = trained.spec.figure_settings.get("x0")
    if x0 is None:
        x0 = np.asarray(trained.dataset["test_x"], dtype=np.float64)[0]
    return tuple(float(v) for v in x0)


def _energy_bump(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-energy-bump.png``: the HNN climbs the gradient of its H for a moment, and keeps the energy."""
    return mischief.energy_bump_figures(trained.task, trained.system, trained.models, _start(trained), fig_dir)


def _reversibility(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-reversibility.png``: forward T, then backward T, per model."""
    return mischief.reversibility_figures(trained.task, trained.models, _start(trained), fig_dir)


def _orbits(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-orbits.png`` and ``.gif``: the paper protocol's seed-0 orbits of truth / baseline / HNN."""
    orbit_figures.orbit_figure(trained.task, energy["paper"], fig_dir / f"{trained.task}-orbits.png")
    orbit_figures.orbit_gif(trained.task, energy["paper"], fig_dir / f"{trained.task}-orbits.gif")
    return {}


def _pixel_compare(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-compare.gif`` and ``-compare-static.png``: the test frames, truth | baseline | HNN."""
    pixel_figures.compare(energy["paper"], fig_dir / f"{trained.task}-compare.gif",
                          fig_dir / f"{trained.task}-compare-static.png")
    return {}


def _pixel_energy(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-energy.png``: the energy of the decoded paths."""
    pixel_figures.energy_plot(energy["paper"], fig_dir / f"{trained.task}-energy.png")
    return {}


def _pixel_phase_space(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-phase-space.png``: each model's latents of the training frames (and the HNN's H)."""
    pixel_figures.phase_space(trained.models, trained.dataset, fig_dir / f"{trained.task}-phase-space.png")
    return {}


def _pixel_add_energy(trained: Trained, energy: dict, fig_dir: Path) -> dict:
    """``<task>-add-energy.gif`` and ``.png``: the paper's demo with ``figure_settings["pixel_add_energy"]``."""
    if "hnn" not in trained.models:
        return {}
    settings = trained.spec.figure_settings["pixel_add_energy"]
    numbers = pixel_figures.add_energy(trained.models["hnn"], energy["paper"]["hnn"]["latents"][0],
                                       fig_dir / f"{trained.task}-add-energy.gif",
                                       fig_dir / f"{trained.task}-add-energy.png", settings)
    return {"add_energy": numbers}


FIGURES = {
    "energy": _energy, "fields": _fields, "integration": _integration, "real_fields": _real_fields,
    "energy_bump": _energy_bump, "reversibility": _reversibility, "orbits": _orbits,
    "pixel_compare": _pixel_compare, "pixel_energy": _pixel_energy, "pixel_phase_space": _pixel_phase_space,
    "pixel_add_energy": _pixel_add_energy,
}


# the figures that draw any one model (``analysis/score.py --plot``); the others need the paper's pair or an H
RUN_FIGURES = ("energy", "fields", "integration", "real_fields", "orbits", "pixel_compare", "pixel_energy",
               "pixel_phase_space")


def draw_figures(trained: Trained, energy: dict, fig_dir, only=None) -> dict:
    """Every figure the task's ``task.py`` names (those of them in ``only``, when given), in its order;
    returns their numbers, merged."""
    unknown = [name for name in trained.spec.figures if name not in FIGURES]
    if unknown:
        raise ValueError(f"experiment-{trained.task}/task.py names unknown figures {unknown}; "
                         f"known: {sorted(FIGURES)}")
    numbers = {}
    for name in trained.spec.figures:
        if only is None or name in only:
            numbers.update(FIGURES[name](trained, energy, Path(fig_dir)))
    return numbers
