"""Reproduce the paper's three tables (train loss, test loss, energy MSE; baseline vs HNN) and
its figures, for every task in this checkout.

    python analysis/reproduce.py                      # full settings, results/
    python analysis/reproduce.py --quick              # smoke run (100 steps), results-quick/
    python analysis/reproduce.py --jobs 2             # two training processes, one thread each
    python analysis/reproduce.py --jobs 2 --backend ray   # each run a Ray task (docs/sweeps.md: clusters)
    python analysis/reproduce.py --jobs 2 --update-docs   # docs/results.md, README headline, docs/figures/

Trains each model from its task's config (``experiment-<task>/train.py``'s ``Config``; a saved
run of the same config is reused), in this process, in ``--jobs N`` worker processes or as Ray tasks (longest runs
first; ``hnn.sweep``), with one progress line for the whole job; a run that fails is
reported and the others go on (the command then exits with code 1, listing them). Then evaluates
the energy MSE under the paper's protocol and a corrected one and draws the figures (per task, as
its ``experiment-<task>/task.py`` says, through ``hnn_analysis.paper.registry``). Writes
``<out>/results.json`` (every number, with versions, commit, seed and the time of each stage),
``<out>/tables.md`` (built from that JSON: ours beside the paper's, marked, and the stage
times) and ``<out>/figures/``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


import hnn
from hnn.io import atomic_write, write_json
from hnn_analysis.paper import registry
from hnn_analysis import commands, plotting, readme
from hnn import sweep, sweep_flags
from hnn_analysis.provenance import provenance
from hnn_analysis.commands import portable_command
from hnn_analysis.paper.tables import MODELS, headline_markdown, tables_markdown

QUICK_STEPS = 100        # --quick: training steps per model (its budget: commands.QUICK_BUDGETS)
QUICK_TRIALS = 5         # --quick: trials of each energy protocol (theirs: 15; a multiple of its 5 splits)
HERE = Path(__file__).resolve().parent


# ----------------------------------------------------------------------------------------------
# evaluation


def load_runs(task: str, runs: dict) -> tuple[registry.Trained, dict]:
    """``(the trained models with the first run's saved args, {label: its row of losses})`` of
    ``runs`` (``{label: run folder}``), each read by the task's ``TaskSpec.load`` or ``hnn.load_run``."""
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


def evaluate_task(task: str, runs: dict, fig_dir: Path | None, num_trials: int | None = None) -> dict:
    """Losses from the saved metrics, energy MSE under every protocol, and the figures (as the
    task's ``task.py`` says, through ``hnn_analysis.paper.registry``). ``runs`` is ``{label: run
    folder}``; the row's ``"seconds"`` holds the time of the evaluation and of the figures.
    ``num_trials``: the trials of each energy protocol, when not its own (``--quick``: ``QUICK_TRIALS``).
    """
    tic = time.perf_counter()
    trained, row = load_runs(task, runs)
    energy = registry.evaluate(trained, num_trials)
    # the figures show the paper's pair; the extra kinds are numbers in their own table
    pair = registry.Trained(task, trained.system, {k: m for k, m in trained.models.items() if k in MODELS},
                            trained.args)
    for name, result in energy.items():
        for kind in trained.models:
            row[kind][f"energy_mse_{name}"] = [result[kind]["mse"], result[kind]["mse_se"]]
        row.setdefault("protocols", {})[name] = result.get("description", name)
    t_eval = time.perf_counter() - tic
    if fig_dir is not None:
        numbers = registry.draw_figures(pair, energy, fig_dir)
        if numbers:
            row["figure_numbers"] = numbers
    row["seconds"] = {"evaluate": t_eval, "figures": time.perf_counter() - tic - t_eval if fig_dir else 0.0}
    return row


# ----------------------------------------------------------------------------------------------
# tables


def _parser() -> argparse.ArgumentParser:
    p = hnn.cli.Parser(prog="reproduce.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=None, help="tasks to run (default: every task of the paper present)")
    p.add_argument("--quick", action="store_true",
                   help=f"smoke run: {QUICK_STEPS} training steps per model (or --steps) and each task's own quick "
                        f"settings (smaller datasets), output in results-quick/; {commands.budget_words('reproduce')}")
    p.add_argument("--steps", type=int, default=None,
                   help="training steps per model, overriding every task's default (with --quick: default "
                        f"{QUICK_STEPS}); a run trained with other steps is retrained")
    p.add_argument("--out", type=Path, default=None, help="output folder (default results/ or results-quick/)")
    p.add_argument("--seed", type=int, default=0, help="seed of the datasets, inits and minibatches")
    p.add_argument("--seeds", type=int, default=1,
                   help="train and evaluate seeds seed .. seed+N-1; tables add mean ± standard error across them")
    p.add_argument("--jobs", type=int, default=1,
                   help="training processes: 1 trains here, one run after another; N > 1 runs N worker "
                        "processes with cores // N threads each, longest runs first (with --backend ray: "
                        "Ray tasks of cores // N threads); evaluation stays here")
    sweep_flags.add_backend_flags(p)
    p.add_argument("--models", nargs="+", default=[], metavar="KIND",
                   choices=[k for k in hnn.cli.model_choices() if k not in MODELS],
                   help="extra model kinds trained and evaluated beside the paper's baseline and HNN, in a table "
                        "of their own (the paper's tables stay as they are): separable, dissipative")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--update-docs", dest="update_docs", action="store_true",
                   help="write docs/results.md from tables.md, the README's headline table, and the curated "
                        "figures in docs/figures/ (full settings only)")
    return p


def _check(parser: argparse.ArgumentParser, args) -> None:
    """Bad values exit with one ``error:`` line (code 2) that names the value and the fix."""
    if args.jobs < 1:
        parser.error(f"--jobs {args.jobs}: must be at least 1 (1 = train in this process)")
    if args.seeds < 1:
        parser.error(f"--seeds {args.seeds}: must be at least 1")
    if args.steps is not None and args.steps < 0:
        parser.error(f"--steps {args.steps}: must be a non-negative number of training steps")
    if args.update_docs and (args.quick or args.steps is not None):
        parser.error("--update-docs writes full-settings results into docs/ and README.md; drop --quick / --steps")
    for task in args.tasks or []:
        if task not in hnn.available_tasks():
            parser.error(f"--tasks {task}: no such task here; choose from {' '.join(hnn.available_tasks())}")
    sweep_flags.check_backend(parser, args)



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
        per_seed = {}
        for seed in own:
            figs = fig_dir if fig_dir is not None and seed == own[0] and spec["note"] is None else None
            per_seed[str(seed)] = evaluate_task(task, {kind: runs[k] for kind, k in keys[seed].items()}, figs,
                                                num_trials)
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


def _meta(args, argv: list[str], seeds: list[int], mode: str, steps: int | None) -> dict:
    return {**provenance(), "command": portable_command(argv), "seed": args.seed, "seeds": seeds, "mode": mode,
            "quick": args.quick, "steps": steps, "jobs": args.jobs, "models": list(MODELS) + list(args.models),
            "available": hnn.tasks.paper_tasks()}


def quick_cuts(tasks: list[str], steps: int | None) -> list[str]:
    """What ``--quick`` cuts from the tasks' own settings, one phrase each, as ``main`` prints them."""
    cuts = []
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


def _mode(args) -> tuple[str, int | None]:
    steps = args.steps if args.steps is not None else (QUICK_STEPS if args.quick else None)
    if args.quick:
        return f"QUICK smoke run, {steps} steps per model: not the paper's settings", steps
    return ("full settings" if steps is None else f"{steps} steps per model: not the paper's settings"), steps


def write_outputs(results: dict, out: Path, update_docs: bool, figures_drawn: bool) -> None:
    """``results.json`` and ``tables.md`` in ``out``; with ``update_docs`` also the docs pages, the
    README's headline table and the curated figures."""
    write_json(out / "results.json", results)
    tables = tables_markdown(results)
    atomic_write(out / "tables.md", lambda tmp: Path(tmp).write_text(tables))
    print("\n" + tables)
    print(f"{'QUICK smoke run: ' if results['meta']['quick'] else ''}total {results['seconds']['total']:.1f} s; "
          f"wrote {out / 'results.json'}, {out / 'tables.md'}" + (f", {out / 'figures'}/" if figures_drawn else ""))
    if update_docs:
        for path in readme.update_results(tables, headline_markdown(results), out / "figures" if figures_drawn else None):
            print(f"updated {path}")


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _parser()
    args = parser.parse_args(argv)
    _check(parser, args)
    out = args.out or hnn.tasks.repo_root() / ("results-quick" if args.quick else "results")
    tasks = args.tasks or hnn.tasks.paper_tasks()
    mode, steps = _mode(args)
    backend = "" if args.backend == "local" else f" --backend {args.backend}"
    print(f"reproduce: tasks {', '.join(tasks)}; {mode}; --jobs {args.jobs}{backend}; output {out}", flush=True)
    cuts = quick_cuts(tasks, steps) if args.quick else []
    if cuts:
        commands.say_quick("reproduce", cuts)
    readme.warn_stale(("headline", "results"))
    seeds = list(range(args.seed, args.seed + args.seeds))
    results = {"meta": {**_meta(args, argv, seeds, mode, steps), "quick_cuts": cuts}, "tasks": {},
               "seconds": {"tasks": {}}}
    start = time.perf_counter()
    rows = table_rows(tasks, args.quick, seeds)
    runs, jobs = sweep.reuse(plan(rows, seeds, out / "runs", steps, args.models))
    trained, seconds = sweep.train_jobs(jobs, args.jobs, out / "logs", args.backend, args.ray_address, args.group,
                                        args.device)
    runs.update(trained)
    results["seconds"].update(seconds)
    tic = time.perf_counter()
    plotting.set_stamp(f"QUICK smoke run ({steps} steps per model): not the paper's settings" if args.quick else "")
    try:
        evaluate_rows(rows, seeds, runs, results, None if args.no_figures else out / "figures", args.models,
                      QUICK_TRIALS if args.quick else None)
    finally:
        plotting.set_stamp("")
    results["seconds"]["evaluation"] = time.perf_counter() - tic
    results["seconds"]["total"] = time.perf_counter() - start
    write_outputs(results, out, args.update_docs, not args.no_figures)
    sweep.exit_if_failed(trained)
    return results


if __name__ == "__main__":
    main()
