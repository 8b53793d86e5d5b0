"""The fits as rungs of the scene studies: a rung is a model kind and how its weights are found (``hnn.fits``).

A kind trained by Adam is its own label (``hnn``); a fit adds its name (``hnn+swim``, ``hnn+library``,
``baseline+sindy``). The studies train, measure, plot and choose rungs as they do kinds: the label keys
every run (``<row>/<label>/seed<s>``), ``kind_of`` gives the kind whose declarations a measurement reads,
``marker`` the fit's marker in the plots. Which rungs a study adds: ``RUNGS`` at the default cell, and
``GRID_RUNGS`` (whose model has a width) across the width x data grid as well.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import hnn
from hnn.sweeps import sweep

# the fits' rungs a scene study adds beside Adam's kinds, where the task takes the kind: the sampled HNN, our
# library of H's terms and pysindy's SINDy, and the pair kind's sampled radial neurons and radial library where a
# task declares bodies (the other pairs, such as separable+library, train through --fit)
RUNGS = ("hnn+swim", "hnn+library", "baseline+sindy", "pairwise+swim", "pairwise+library")
GRID_RUNGS = ("hnn+swim", "pairwise+swim")   # ... and across its width x data grid (a sampled layer has a width)


def label(kind: str, fit: str = "adam") -> str:
    """``'hnn'`` for Adam's, ``'hnn+swim'`` for a fit's."""
    return kind if fit == "adam" else f"{kind}+{fit}"


def kind_of(rung: str) -> str:
    """The model kind of a rung label."""
    return rung.split("+", 1)[0]


def fit_of(rung: str) -> str:
    """The fit of a rung label (``'adam'`` for a bare kind)."""
    return rung.split("+", 1)[1] if "+" in rung else "adam"


def is_library(rung: str) -> bool:
    """Whether the rung's model is a sum of written-out terms (ours or SINDy's): it prints as equations."""
    return hnn.fits.FITS[fit_of(rung)].prints_equation


def describe(rung: str, width: int, fraction: float) -> str:
    """``'hnn, width 32, 0.5 of the data'``; a library's rung has no width: ``'hnn+library, 1 of the data'``."""
    return f"{rung}, " + ("" if is_library(rung) else f"width {width}, ") + f"{fraction:g} of the data"


def marker(rung: str) -> str:
    """The rung's marker in a plot (its fit's; Adam's a circle)."""
    return hnn.fits.FITS[fit_of(rung)].marker


def fit_rungs(kinds, rungs=RUNGS) -> list[str]:
    """The ``rungs`` whose kind is among ``kinds`` (a study's), where their fit's package is installed (SINDy's)."""
    out = []
    for rung in rungs:
        row = hnn.fits.FITS[fit_of(rung)]
        if row.package == "pysindy" and hnn.fits.sindy.version() is None:
            continue
        if kind_of(rung) in kinds:
            out.append(rung)
    return out


def builds(config) -> bool:
    """Whether the model of run ``config`` builds from what its task declares (a small one, untrained): the pair kind
    needs the task's bodies, a constrained kind its constraint graph; the builder's ValueError says which is missing."""
    spec = hnn.specs.run_specs(config).model
    try:
        hnn.kinds.model_from_spec(dataclasses.replace(spec, hidden_dim=min(spec.hidden_dim or 4, 4)))
    except ValueError:
        return False
    return True


def jobs(rows: list[dict], seeds: list[int], runs_dir: Path, rungs, fits) -> list[sweep.Job]:
    """The runs of the fit ``rungs`` on every row and seed (``fits(task, label)``: whether the rung fits the
    row's states), keyed ``<row>/<label>/seed<s>`` as a kind's: a fit takes the row's fields, its model and its
    fit (no optimizer steps to cut); a row with ``fit_rows`` (a quick study's) fits at most that many training
    rows (``capped``). Their ``expected_seconds`` are left to the plan (``hnn_analysis.plan.fit_seconds``)."""
    out = []
    for row in rows:
        for rung in rungs:
            if "+" not in rung or not fits(row["task"], rung):
                continue
            for seed in row.get("seeds") or seeds:
                fields = {**row["fields"], "model": kind_of(rung), "fit": fit_of(rung), "seed": seed,
                          "save_dir": str(runs_dir)}
                config = hnn.tasks.task_config(row["task"], fields)
                if row.get("fit_rows"):
                    config = capped(config, row["fit_rows"])
                out.append(sweep.Job(f"{row['row']}/{rung}/seed{seed}", row["task"], config))
    return out


def training_rows(config) -> int:
    """The training rows a run of ``config`` fits: its dataset's (built, or read from its cache in the run's
    ``save_dir``) at its ``train_fraction``."""
    return int(round(len(config.dataset()["x"]) * config.train_fraction))


def capped(config, rows: int):
    """``config`` with its ``train_fraction`` cut so that it fits at most ``rows`` training rows (as it is where
    it fits no more): a quick study's fit, whose solve grows with its rows (the 3-body library's 100000 rows
    took 90 s on a quiet 2-core box)."""
    have = training_rows(config)
    if have <= rows:
        return config
    return dataclasses.replace(config, train_fraction=float(f"{config.train_fraction * rows / have:.3g}"))


def equation(directory) -> str | None:
    """The equation a library run printed (its metrics.json's ``history.fit.equation``), else None."""
    try:
        metrics = json.loads((Path(directory) / "metrics.json").read_text())
    except (OSError, ValueError):
        return None
    return ((metrics.get("history") or {}).get("fit") or {}).get("equation")
