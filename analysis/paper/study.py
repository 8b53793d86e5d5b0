"""The paper's study as a library: the rows of its tables as runs, each row's kinds and the sweep's
jobs, the trained runs loaded and evaluated (energy MSE under every protocol, the figures), and what
``--quick`` cuts. ``analysis/reproduce.py`` is its command; the scene study and the measured study
train and read their runs through it too.

    rows = study.table_rows(tasks, quick=False, seeds=[0])
    found, jobs = sweep.reuse(study.plan(rows, [0], out / "runs", steps=None))
    ...
    study.evaluate_rows(rows, [0], runs, results, out / "figures")
"""
from __future__ import annotations

import math
import time
from pathlib import Path

from typing import TYPE_CHECKING

import hnn
from hnn_analysis.paper.tables import MODELS

if TYPE_CHECKING:       # torch-free at import: reproduce.py checks its flags before the sweep and registry load
    from hnn.sweeps import sweep
    from hnn_analysis.paper import registry

QUICK_STEPS = 100        # --quick: training steps per model (its budget: commands.QUICK_BUDGETS)
QUICK_TRIALS = 5         # --quick: trials of each energy protocol (theirs: 15; a multiple of its 5 splits)
# --quick: a task whose dataset takes longer than this to build (its TaskSpec.data_cost, on the reference box of
# hnn_analysis.plan) is left out unless --tasks names it (the pixels' frames: 20 s of the 60 s)
QUICK_DATA_SECONDS = 5.0


def load_runs(task: str, runs: dict) -> tuple[registry.Trained, dict]:
    """``(the trained models with the first run's saved args, {label: its row of losses})`` of
    ``runs`` (``{label: run folder}``), each read by the task's ``TaskSpec.load`` or ``hnn.load_run``."""
    from hnn_analysis.paper import registry
    load = hnn.task_spec(task).load or hnn.load_run
    models, row, first_args = {}, {}, None
    for label, directory in runs.items():
        models[label], args, metrics = load(directory)
        first_args = first_args or args
        row[label] = {"train_loss": [metrics["train_loss"], metrics["train_loss_se"]],
                      "test_loss": [metrics["test_loss"], metrics["test_loss_se"]],
                      "train_seconds": metrics.get("train_seconds"), "data_seconds": metrics.get("data_seconds"),
                      "total_steps": args["total_steps"]}
    return registry.Trained(task, hnn.load_task(task), models, first_args), row


def evaluate_seeds(task: str, runs: list[dict], fig_dir: Path | None, num_trials: int | None = None) -> list[dict]:
    """Each seed's row: losses from the saved metrics of its ``runs`` (``{label: run folder}``, the same
    labels in each seed), energy MSE under every protocol with the seeds' models scored as groups
    (``registry.evaluate_seeds``: the truth integrated once), and the figures from the first seed (as
    the task's ``task.py`` says, through ``hnn_analysis.paper.registry``). A row's ``"seconds"``: the
    group's evaluation time shared equally, and the figures'. ``num_trials``: the trials of each energy
    protocol, when not its own (``--quick``: ``QUICK_TRIALS``)."""
    from hnn_analysis.paper import registry
    tic = time.perf_counter()
    loaded = [load_runs(task, by_label) for by_label in runs]
    energies = registry.evaluate_seeds([trained for trained, _ in loaded], num_trials)
    t_eval = (time.perf_counter() - tic) / len(runs)
    out = []
    for (trained, row), energy in zip(loaded, energies):
        for name, result in energy.items():
            for kind in trained.models:
                if result[kind]["mse"] is not None:
                    row[kind][f"energy_mse_{name}"] = [result[kind]["mse"], result[kind]["mse_se"]]
                elif "rollout failed" in result[kind]["why"]:     # a model that blew up or stalled: inf, and why
                    row[kind][f"energy_mse_{name}"] = [math.inf, 0.0]
                    row[kind]["diverged"] = result[kind]["why"]
                # else a protocol that does not apply (a learned map's): no number
            row.setdefault("protocols", {})[name] = result.get("description", name)
        row["seconds"] = {"evaluate": t_eval, "figures": 0.0}
        out.append(row)
    if fig_dir is not None:
        trained, energy = loaded[0][0], energies[0]
        tic = time.perf_counter()
        # the figures show the paper's pair; the extra kinds are numbers in their own table
        pair = registry.Trained(task, trained.system, {k: m for k, m in trained.models.items() if k in MODELS},
                                trained.args)
        numbers = registry.draw_figures(pair, energy, fig_dir)
        if numbers:
            out[0]["figure_numbers"] = numbers
        out[0]["seconds"]["figures"] = time.perf_counter() - tic
    return out


def table_rows(tasks: list[str], quick: bool, seeds: list[int] | None = None) -> list[dict]:
    """The rows of the tables: each task in the paper's setting, then its variants (``TaskSpec.variants``).

    A row is ``{"row": name, "task": task, "fields": its runs' config fields, "note": why or None,
    "seeds": its seeds}``: ``seeds``, extended to the task's ``TaskSpec.min_seeds`` when there are two
    or more (None: the caller's seeds).
    """
    rows = []
    for task in tasks:
        spec = hnn.task_spec(task)
        fields = {**spec.settings, **(spec.quick if quick else {})}
        own = seeds
        if seeds is not None and 2 <= len(seeds) < spec.min_seeds:
            own = list(range(seeds[0], seeds[0] + spec.min_seeds))
        rows.append({"row": task, "task": task, "fields": fields, "note": None, "seeds": own})
        for suffix, (changes, why) in spec.variants.items():
            name = f"{task}-{suffix}"
            rows.append({"row": name, "task": task, "fields": {**fields, **changes, "name": name}, "note": why,
                         "seeds": own})
    return rows


def row_models(task: str, models=MODELS) -> list[str]:
    """The kinds of ``models`` that ``task``'s ``--model`` takes (its config's), the paper's pair first."""
    takes = hnn.cli.model_choices(hnn.load_task(task, "train").Config)
    return [kind for kind in dict.fromkeys(MODELS + tuple(models)) if kind in takes]


def plan(rows: list[dict], seeds: list[int], runs_dir: Path, steps: int | None,
         models=MODELS) -> list[sweep.Job]:
    """The run of every row and seed, for the paper's two models and the extra ``models`` kinds
    the row's task has; ``steps`` overrides the tasks' ``total_steps``."""
    from hnn.sweeps import sweep
    jobs = []
    for spec in rows:
        for seed in spec.get("seeds") or seeds:
            for kind in row_models(spec["task"], models):
                fields = {**spec["fields"], "model": kind, "seed": seed, "save_dir": str(runs_dir)}
                if steps is not None:
                    fields["total_steps"] = steps
                jobs.append(sweep.Job(f"{spec['row']}/{kind}/seed{seed}", spec["task"],
                                      hnn.tasks.task_config(spec["task"], fields)))
    return jobs


def rung_jobs(tasks, seeds: list[int], runs_dir: Path, quick: bool, rungs) -> list[sweep.Job]:
    """The run of every rung of every task at every seed: ``rungs(task)`` gives ``{label: fields}``; a quick run
    takes the task's quick settings and, where Adam trains it, ``QUICK_STEPS``. A least-squares rung is planned at
    a second (its solve), a trained one at its measured rate."""
    from hnn.sweeps import sweep
    jobs = []
    for task in tasks:
        spec = hnn.task_spec(task)
        for label, fields in rungs(task).items():
            solved = fields.get("fit", "adam") != "adam"
            for seed in seeds:
                values = {**spec.settings, **(spec.quick if quick else {}), **fields, "seed": seed,
                          "save_dir": str(runs_dir), **({"total_steps": QUICK_STEPS} if quick and not solved else {})}
                jobs.append(sweep.Job(f"{task}/{label}/seed{seed}", task, hnn.tasks.task_config(task, values),
                                      expected_seconds=1.0 if solved else None))
    return jobs


def _stage_seconds(keys: dict, per_seed: dict, run_seconds: dict) -> dict:
    """One row's seconds: dataset, training per model (summed over seeds), evaluation, figures."""
    stage = {"data": None, "train": {}, "evaluate": 0.0, "figures": 0.0}
    for seed, by_kind in keys.items():
        for kind, key in by_kind.items():
            timing = run_seconds.get(key)
            if timing:
                stage["data"] = (stage["data"] or 0.0) + (timing["data"] or 0.0)
                stage["train"][kind] = stage["train"].get(kind, 0.0) + (timing["train"] or 0.0)
        for part in ("evaluate", "figures"):
            stage[part] += per_seed[str(seed)]["seconds"][part]
    return stage


def evaluate_rows(rows: list[dict], seeds: list[int], runs: dict, results: dict, fig_dir: Path | None,
                  models=MODELS, num_trials: int | None = None) -> None:
    """Evaluate every row at every seed into ``results["tasks"]`` (figures for the first seed of
    each task's paper row); a task that cannot run here goes to ``results["skipped"]`` once."""
    from hnn.sweeps import sweep
    progress = sweep.Progress(len(rows))
    print(f"  {progress.tag()} evaluating {len(rows)} rows" + (" and drawing their figures" if fig_dir else ""),
          flush=True)
    for spec in rows:
        progress.advance()
        name, task = spec["row"], spec["task"]
        if task in results.get("skipped", {}):
            continue
        own = spec.get("seeds") or seeds
        keys = {seed: {kind: f"{name}/{kind}/seed{seed}" for kind in row_models(task, models)} for seed in own}
        failed = [runs[k] for by_kind in keys.values() for k in by_kind.values() if isinstance(runs[k], Exception)]
        if failed:
            results.setdefault("skipped", {})[task] = str(failed[0])
            print(f"  {progress.tag()} {task:11s} SKIPPED (the reason is above)", flush=True)
            continue
        figs = fig_dir if spec["note"] is None else None
        rows_by_seed = evaluate_seeds(task, [{kind: runs[k] for kind, k in keys[seed].items()} for seed in own], figs,
                                      num_trials)
        per_seed = {str(seed): row for seed, row in zip(own, rows_by_seed)}
        row = dict(per_seed[str(own[0])], task=task, note=spec["note"])
        if len(per_seed) > 1:
            row["per_seed"] = per_seed
        stage = _stage_seconds(keys, per_seed, results["seconds"]["runs"])
        row.pop("seconds", None)
        results["tasks"][name] = row
        results["seconds"]["tasks"][name] = stage
        print(f"  {progress.tag()} {name:11s} evaluated ({stage['evaluate']:.1f} s)"
              + (f", figures ({stage['figures']:.1f} s)" if fig_dir is not None and spec["note"] is None else ""),
              flush=True)


def quick_cuts(tasks: list[str], steps: int | None, left_out: list[str] = ()) -> list[str]:
    """What ``--quick`` cuts from the tasks' own settings, one phrase each, as ``main`` prints them; ``left_out``:
    the paper's tasks it leaves out for their dataset's cost (``quick_tasks``)."""
    cuts = []
    if left_out:
        cuts.append(f"tasks: {', '.join(left_out)} left out (a dataset over {QUICK_DATA_SECONDS:g} s to build on the "
                    "reference box: " + ", ".join(f"{t} {hnn.task_spec(t).data_cost:g} s" for t in left_out)
                    + "; --tasks names one to reproduce it)")
    if steps is not None:
        own = {task: hnn.tasks.task_config(task, hnn.task_spec(task).settings).total_steps for task in tasks}
        cuts.append(f"{steps} training steps a model of the tasks' own "
                    + ", ".join(f"{n} ({task})" for task, n in own.items()))
    for task in tasks:
        spec = hnn.task_spec(task)
        config = hnn.tasks.task_config(task, spec.settings)
        cuts += [f"{task}: {key} {value} of {getattr(config, key)}" for key, value in spec.quick.items()]
    # the tasks measured by hnn.evaluate_energy (a task with its own evaluate keeps its protocols)
    own = [hnn.task_spec(task).protocols.values() for task in tasks if hnn.task_spec(task).evaluate is None]
    trials = {protocol.num_trials for protocols in own for protocol in protocols if protocol.x0 != "test_segment"}
    if trials:
        cuts.append(f"energy MSE: {QUICK_TRIALS} trials of each protocol's {', '.join(map(str, sorted(trials)))}")
    return cuts


def quick_tasks(tasks: list[str]) -> list[str]:
    """The tasks ``--quick`` takes of ``tasks`` when none is named: those whose dataset builds within
    ``QUICK_DATA_SECONDS`` on the reference box (``TaskSpec.data_cost``)."""
    return [task for task in tasks if hnn.task_spec(task).data_cost <= QUICK_DATA_SECONDS]


def reference_plan(tasks: list[str], steps: int = QUICK_STEPS) -> list:
    """``reproduce.py --quick``'s plan of ``tasks`` on the quick budgets' reference box (``hnn_analysis.plan``:
    declared costs, nothing built): the plan's own timing of its configs (``plan.reference_timing``), its training
    (``plan.reference_seconds``), its datasets (each task's ``TaskSpec.data_cost``) and its evaluation
    (``evaluation_stage``)."""
    from hnn_analysis import plan as plans
    rows = table_rows(tasks, True, [0])
    jobs = plan(rows, [0], Path("runs"), steps)
    training = plans.Stage("train", len(jobs), "runs", sum(plans.reference_seconds(job) for job in jobs),
                           "each run's declared cost on the reference box")
    return [plans.reference_timing(jobs), training, data_stage(tasks), evaluation_stage(rows)]


def data_stage(tasks: list[str]):
    """The datasets the runs build, once a task, at each task's declared ``TaskSpec.data_cost``."""
    from hnn_analysis import plan as plans
    return plans.Stage("build", len(tasks), "datasets" if len(tasks) != 1 else "dataset",
                       plans.reference_data_seconds(tasks), "each task's declared build on the reference box")


def evaluation_stage(rows: list[dict]):
    """The --quick evaluation of ``rows`` on the reference box: each task's row at its ``TaskSpec.evaluate_cost`` (its
    energy protocols at ``QUICK_TRIALS`` trials and its figures). A variant row draws no figure, and its protocols
    are what its task's cost leaves beside the figures (3body-clean's: 0.0 s of the 17 s of the six rows on a quiet
    2-core box, 643e3a4): priced as its task's, the rows were planned at 26.5 s, 1.54x."""
    from hnn_analysis import plan as plans
    return plans.Stage("evaluate", len(rows), "rows", sum(hnn.task_spec(row["task"]).evaluate_cost for row in rows
                                                          if row["row"] == row["task"]),
                       "each task's declared evaluation and figures on the reference box; a variant row's: none")


def stages(tasks: list[str], rows: list[dict], training, quick: bool) -> list:
    """``reproduce.py``'s plan around its ``training`` stage: a quick run's datasets and evaluation at their
    declared costs (the reference box's); a full run's evaluation timed as it goes."""
    from hnn_analysis import plan as plans
    if quick:
        return [data_stage(tasks), training, evaluation_stage(rows)]
    return [training, plans.Stage("evaluate", len(rows), "rows")]
