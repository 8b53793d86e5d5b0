"""The least-squares fits on the paper's tasks and the chain, beside Adam and SINDy, as a library: the rungs
each task trains (``rungs``), the sweep's jobs (``plan``), what is measured of each run (``measure``) and
the two tables (``accuracy_table``: the sampled and library fits against Adam's HNN; ``library_table``:
our library against SINDy and the networks). ``analysis/fits/fit_tasks.py`` is its command.

A rung is a model kind and how its weights are found: ``hnn`` and ``baseline`` by Adam (each task's own
settings, the paper's runs), ``hnn+swim`` (a sampled layer of ``SWIM_WIDTH`` neurons, the last layer by
least squares), ``hnn+library`` (H as a sparse sum of terms) and ``baseline+sindy`` (pysindy's SINDy, where
it is installed); on a task that declares its bodies (2body, 3body), the pair kind by Adam (``pairwise``, V at
``RADIAL_WIDTH``), by
the task's width of sampled radial neurons (``pairwise+swim``) and by the radial library (``pairwise+library``).
Measured per seed: the test loss (the saved run's), the energy MSE of every protocol of the task (``registry.evaluate``: the paper's and the corrected; the chain: along CHNN's 3 s rollouts,
below) and the training seconds on one thread (``hnn_analysis.training_cost``: Adam's steps at their
timed rate, a fit's whole solve). The pixel task is not one: its latent coordinates are learned by the
autoencoder, which no linear solve can find (``--fit`` refuses it).
"""
from __future__ import annotations

import math
import statistics
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.models.pair import RADIAL_WIDTH
from hnn.sweeps import sweep
from hnn_analysis.paper import study
from hnn_analysis.training_cost import training_cost
from hnn_analysis.pages import generated_by

TASKS = ("spring", "pend", "real", "2body", "3body", "chain")
SWIM_WIDTH = 1000          # a sampled layer needs more neurons than a trained one; its solve stays seconds
# label -> the run's fields: Adam's kinds at the task's own settings, then the fits; the pair kind's three where
# the task declares its bodies (2body, 3body: ``rungs``): Adam's V at the pair kind's RADIAL_WIDTH; its sampled
# neurons read one distance, at the task's width (200 fit the 3-body's H to a relative error of 1.9e-3 in 23 s, 1000
# to 6.3e-4 in 137 s and 5 GB; seed 0, one thread, 2-core box at load 2), the runs analysis/bodies.py --paper trains
RUNGS = {"hnn": {"model": "hnn"}, "baseline": {"model": "baseline"},
         "hnn+swim": {"model": "hnn", "fit": "swim", "hidden_dim": SWIM_WIDTH},
         "hnn+library": {"model": "hnn", "fit": "library"},
         "baseline+sindy": {"model": "baseline", "fit": "sindy"},
         "pairwise": {"model": "pairwise", "hidden_dim": RADIAL_WIDTH},
         "pairwise+swim": {"model": "pairwise", "fit": "swim"},
         "pairwise+library": {"model": "pairwise", "fit": "library"}}
ADAM = ("hnn", "baseline")
# the rungs whose model is a network (the library table's "every network")
NETWORKS = ("hnn", "baseline", "hnn+swim", "pairwise", "pairwise+swim")
LIBRARIES = ("hnn+library", "pairwise+library")      # the library table's rows: ours over x = [q, p], and over r
NEAR = 2.0                 # "as accurate": a mean within this factor of Adam's HNN on test loss and energy MSE
# the chain (CHNN's 2-bob protocol, trained on [q, qdot]): its rollouts from CHNN's test starts
CHAIN_STARTS, CHAIN_RTOL = 25, 1e-7
# where the chain's fits read its states: dx/dt at every state (its Adam runs fit 4-step snippets)
FIT_FIELDS = {"chain": {"objective": "derivative"}}


def own_objective(task: str, label: str) -> bool:
    """Whether the fit ``label`` trains on another objective than ``task``'s Adam rungs (the chain's fits read
    dx/dt, its Adam runs 4-step snippets): its test loss then measures another thing and does not compare."""
    return label not in ADAM and "objective" in FIT_FIELDS.get(task, {})


def rungs(task: str) -> dict[str, dict]:
    """The rungs ``task`` trains: each whose kind its ``--model`` takes, whose fit applies to that kind, whose
    model builds from what the task declares (the pair kind: its bodies), and whose package is installed (SINDy's)."""
    takes = hnn.cli.model_choices(hnn.load_task(task, "train").Config)
    out = {}
    for label, fields in RUNGS.items():
        fit = hnn.fits.FITS[fields.get("fit", "adam")]
        if fields["model"] not in takes or (fit.kinds is not None and fields["model"] not in fit.kinds):
            continue
        if not _builds(task, fields):
            continue
        if fit.package == "pysindy" and hnn.fits.sindy.version() is None:
            continue
        # a library's degree is its task's (experiment-3body/train.py keeps its 12 coordinates' library small)
        out[label] = {**fields, **(FIT_FIELDS.get(task, {}) if fit.solved else {})}
    return out


def _builds(task: str, fields: dict) -> bool:
    """Whether the model of ``fields`` on ``task`` builds from what the task declares (a small one): the pair kind's
    builder refuses a task that declares no bodies (spring, the chain) with a ValueError."""
    spec = hnn.specs.run_specs(hnn.tasks.task_config(task, {**fields, "hidden_dim": 4})).model
    try:
        hnn.kinds.model_from_spec(spec)
    except ValueError:
        return False
    return True


def plan(tasks, seeds: list[int], runs_dir: Path, quick: bool) -> list[sweep.Job]:
    """Every task's rungs at every seed (``study.rung_jobs``; a quick run: the task's quick settings and
    ``study.QUICK_STEPS``)."""
    return study.rung_jobs(tasks, seeds, runs_dir, quick, rungs)


def _chain_energy(task: str, models: dict) -> dict:
    """The chain's numbers of each model: CHNN's rollout error (the geometric mean over 3 s of the Cartesian
    relative error, ``CHAIN_STARTS`` of their test starts) and the energy MSE along the same rollouts, the
    true energy of the predicted states against the truth's: ``{label: {"energy_mse": [mean, se], "rollout"}}``."""
    protocols = hnn.load_task(task, "protocols")
    data = hnn.load_task(task)
    chain = data.chain_for(2)
    z0 = protocols.chnn_test_starts(chain)[:CHAIN_STARTS].to(torch.float64)
    t = np.arange(protocols.CHNN["points"]) * protocols.CHNN["dt"]
    truth = data.trajectories(chain, z0, t)
    e_true = chain.energy(truth.reshape(-1, truth.shape[-1])).reshape(truth.shape[:2])
    out = {}
    for label, model in models.items():
        field = hnn.evaluation.float64_copy(model).observed_field("velocity")
        try:
            with torch.no_grad():
                pred = hnn.rollout(field, z0, t, method="dopri5", rtol=CHAIN_RTOL, atol=CHAIN_RTOL)
        except hnn.DivergenceError as err:      # a model whose flow leaves the chain's states: its numbers are inf
            out[label] = {"energy_mse": (math.inf, 0.0), "rollout": math.inf, "diverged": str(err).split(":")[0]}
            continue
        e_pred = chain.energy(pred.reshape(-1, pred.shape[-1])).reshape(pred.shape[:2])
        gap = ((e_pred - e_true) ** 2).numpy()
        out[label] = {"energy_mse": hnn.metrics.energy_mse(e_true.numpy(), e_pred.numpy()),
                      "rollout": float(np.mean(protocols.rollout_error(chain, pred, truth))),
                      "finite": bool(np.isfinite(gap).all())}
    return out


def measure(task: str, by_seed: dict[int, dict], quick: bool) -> dict:
    """``{label: {seed: numbers}}`` of one task's runs (``by_seed``: ``{seed: {label: run folder}}``): the saved
    losses, the energy MSE of each protocol (the chain's own, ``_chain_energy``) and ``train_seconds``."""
    seeds = sorted(by_seed)
    out: dict[str, dict] = {}
    if hnn.task_spec(task).protocols:
        # a model whose rollout blows up scores inf and says why (``study.evaluate_seeds``)
        rows = study.evaluate_seeds(task, [by_seed[s] for s in seeds], None, study.QUICK_TRIALS if quick else None)
    else:
        rows = []
        for seed in seeds:
            trained, row = study.load_runs(task, by_seed[seed])
            for label, numbers in _chain_energy(task, trained.models).items():
                row[label]["energy_mse_rollout"] = list(numbers["energy_mse"])
                row[label]["rollout_error"] = numbers["rollout"]
            rows.append(row)
    for seed, row in zip(seeds, rows):
        for label, directory in by_seed[seed].items():
            numbers = {k: v for k, v in row[label].items() if k != "total_steps"}
            numbers["train_seconds"] = training_cost(task, hnn.load_run(directory)[1])["seconds"]
            numbers["run"] = Path(directory).name
            metrics = hnn.load_run(directory)[2]
            numbers["equation"] = (metrics.get("history") or {}).get("fit", {}).get("equation")
            out.setdefault(label, {})[seed] = numbers
    return out


def energy_key(per_seed: dict) -> str:
    """The energy MSE a table reads: the corrected protocol's (the task's true H), else the paper's, else the
    chain's along its rollouts."""
    first = next(iter(per_seed.values()))
    return next(k for k in ("energy_mse_corrected", "energy_mse_paper", "energy_mse_rollout") if first.get(k))


def across(per_seed: dict, key: str) -> tuple[float, float] | None:
    """(mean, standard error) over seeds of ``key`` (a ``[mean, se]`` pair's mean, or a number); a mean of
    inf where any seed's rollout blew up or stalled (the second number: how many)."""
    values = [(v[key][0] if isinstance(v[key], list) else v[key]) for v in per_seed.values() if v.get(key) is not None]
    if not values:
        return None
    if not all(math.isfinite(v) for v in values):
        return (math.inf, float(sum(not math.isfinite(v) for v in values)))
    return hnn.metrics.mean_and_se(values) if len(values) > 1 else (float(values[0]), 0.0)


def seconds(per_seed: dict) -> float:
    return statistics.median(v["train_seconds"] for v in per_seed.values())


def _g(pair) -> str:
    if pair is None:
        return "n/a"
    if not math.isfinite(pair[0]):      # (inf, how many seeds' rollouts blew up or stalled)
        return f"rollout failed ({pair[1]:.0f} seed{'s' if pair[1] != 1 else ''})"
    return f"{pair[0]:.3g}" + (f" ± {pair[1]:.2g}" if pair[1] else "")


def accuracy_table(results: dict) -> list[str]:
    """Per task: each rung's test loss, energy MSE and training seconds, and for each fit whether it is as
    accurate as Adam's HNN (both means within ``NEAR``x; the energy MSE alone where the fit's objective is its
    own, ``own_objective``) and by what factor it is cheaper."""
    lines = ["| task | rung | test loss | energy MSE | train s (one thread) | as accurate as Adam's HNN? | cheaper by |",
             "| --- | --- | --- | --- | ---: | --- | ---: |"]
    for task, by_label in results["tasks"].items():
        reference = by_label.get("hnn")
        for label, per_seed in by_label.items():
            key = energy_key(per_seed)
            loss, energy, cost = across(per_seed, "test_loss"), across(per_seed, key), seconds(per_seed)
            verdict, factor = "", ""
            own = own_objective(task, label)
            if reference and label not in ADAM:
                pairs = [(energy, across(reference, key))] + ([] if own else [(loss, across(reference, "test_loss"))])
                close = all(ours is not None and ref is not None and ours[0] <= NEAR * ref[0] for ours, ref in pairs)
                verdict = "yes" if close else "no"
                factor = f"{seconds(reference) / cost:.3g}x" if close and cost > 0 else ""
            shown = _g(loss) + (" (dx/dt)" if own else "")
            lines.append(f"| {task} | {label} | {shown} | {_g(energy)} | {cost:.3g} | {verdict} | {factor} |")
    return lines


def library_table(results: dict) -> list[str]:
    """Per task and library (``LIBRARIES``: the HNN's over x = [q, p], the pair kind's over r where the task
    declares bodies): its energy MSE against SINDy's (their ratio, target within 10x) and every network's (is it
    below all of them?), and the equation each library found (seed 0)."""
    lines = ["| task | library | energy MSE | SINDy: energy MSE | library / SINDy | best network (energy MSE) | "
             "library below every network? | library's H (seed 0) | SINDy's dx/dt (seed 0) |",
             "| --- | --- | --- | --- | ---: | --- | --- | --- | --- |"]
    for task, by_label in results["tasks"].items():
        for library in (label for label in LIBRARIES if label in by_label):
            key = energy_key(by_label[library])
            ours = across(by_label[library], key)
            sindy = across(by_label["baseline+sindy"], key) if "baseline+sindy" in by_label else None
            nets = {label: pair for label in NETWORKS if label in by_label and (pair := across(by_label[label], key))}
            best = min(nets, key=lambda k: nets[k][0]) if nets else None
            ratio = (f"{ours[0] / sindy[0]:.3g}" if sindy and 0 < sindy[0] < math.inf and math.isfinite(ours[0])
                     else "n/a")
            below = "yes" if nets and all(ours[0] < v[0] for v in nets.values()) else "no"
            lines.append(f"| {task} | {library} | {_g(ours)} | {_g(sindy)} | {ratio} | {best} ({_g(nets.get(best))}) | "
                         f"{below} | `{_equation(by_label, library)}` | `{_equation(by_label, 'baseline+sindy')}` |")
    return lines


def _equation(by_label: dict, label: str, width: int = 90) -> str:
    """The equation the first seed's run of ``label`` printed, cut to ``width`` characters."""
    per_seed = by_label.get(label) or {}
    text = (per_seed[min(per_seed)].get("equation") or "") if per_seed else ""
    return (text[:width] + " ...") if len(text) > width else text


def markdown(results: dict) -> str:
    meta = results["meta"]
    head = [generated_by(meta, f"torch {meta['torch']}, {meta['cores']} cores, {meta['cpu']}; seeds {meta['seeds']}"
                         + ("; QUICK smoke run, not the study's settings" if meta.get("quick") else "")) + "."]
    return "\n".join(head + ["", "**Fits beside Adam**", ""] + accuracy_table(results)
                     + ["", "**The library beside SINDy**", ""] + library_table(results)) + "\n"

