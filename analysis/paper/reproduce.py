"""Reproduce the paper's three tables (train loss, test loss, energy MSE; baseline vs HNN) and
its figures, for every task in this checkout.

    python analysis/reproduce.py                      # full settings, results/
    python analysis/reproduce.py --quick              # smoke run (100 steps), results-quick/
    python analysis/reproduce.py --jobs 2             # two training processes, one thread each
    python analysis/reproduce.py --jobs 2 --backend ray   # each run a Ray task (docs/sweeps.md: clusters)
    python analysis/reproduce.py --jobs 2 --update-docs   # docs/results.md, README headline, docs/figures/

Trains each model from its task's config (``experiment-<task>/train.py``'s ``Config``; a saved
run of the same config is reused), in this process, in ``--jobs N`` worker processes or as Ray tasks (longest runs
first; ``hnn.sweeps.sweep``), with one progress line for the whole job; a run that fails is
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
from hnn.threads import torch_threads
from hnn_analysis.paper import study
from hnn_analysis import commands, pages, plan, plotting
from hnn.sweeps import flags as sweep_flags
from hnn_analysis.commands import portable_command
from hnn_analysis.paper.tables import MODELS, headline_markdown, tables_markdown
# torch-free to here: main checks the flags before it imports the sweep (torch)
def _parser() -> argparse.ArgumentParser:
    p = hnn.cli.Parser(prog="reproduce.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=None, help="tasks to run (default: every task of the paper present)")
    commands.add_flags(p, quick=f"smoke run: {study.QUICK_STEPS} training steps per model (or --steps) and each task's "
                                f"own quick settings (smaller datasets), output in results-quick/; "
                                f"{commands.budget_words('reproduce')}")
    p.add_argument("--steps", type=int, default=None,
                   help="training steps per model, overriding every task's default (with --quick: default "
                        f"{study.QUICK_STEPS}); a run trained with other steps is retrained")
    commands.add_flags(p, out="output folder (default results/ or results-quick/)")
    p.add_argument("--seed", type=int, default=0, help="seed of the datasets, inits and minibatches")
    commands.add_flags(p, seeds="train and evaluate seeds seed .. seed+N-1; tables add mean ± standard error across them",
                       jobs="training processes: 1 trains here, one run after another; N > 1 runs N worker "
                            "processes with cores // N threads each, longest runs first (with --backend ray: "
                            "Ray tasks of cores // N threads); evaluation stays here")
    sweep_flags.add_backend_flags(p)
    p.add_argument("--models", nargs="+", default=[], metavar="KIND",
                   choices=[k for k in hnn.cli.model_choices() if k not in MODELS],
                   help="extra model kinds trained and evaluated beside the paper's baseline and HNN, in a table "
                        "of their own (the paper's tables stay as they are): separable, dissipative")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    commands.add_flags(p, update_docs="write docs/results.md from tables.md, the README's headline table, and the "
                                      "curated figures in docs/figures/ (full settings only)")
    return p


def _check(parser: argparse.ArgumentParser, args) -> None:
    """Bad values exit with one ``error:`` line (code 2) that names the value and the fix."""
    if args.steps is not None and args.steps < 0:
        parser.error(f"--steps {args.steps}: must be a non-negative number of training steps")
    if args.update_docs and (args.quick or args.steps is not None):
        parser.error("--update-docs writes full-settings results into docs/ and README.md; drop --quick / --steps")
    for task in args.tasks or []:
        if task not in hnn.tasks.task_names():
            parser.error(f"--tasks {task}: no such task here; choose from {' '.join(hnn.tasks.task_names())}")
    sweep_flags.check_backend(parser, args)


def _meta(args, argv: list[str], seeds: list[int], mode: str, steps: int | None) -> dict:
    from hnn_analysis.provenance import provenance
    return {**provenance(), "command": portable_command(argv), "seed": args.seed, "seeds": seeds, "mode": mode,
            "quick": args.quick, "steps": steps, "jobs": args.jobs, "models": list(MODELS) + list(args.models),
            "available": hnn.tasks.paper_tasks()}


def _mode(args) -> tuple[str, int | None]:
    steps = args.steps if args.steps is not None else (study.QUICK_STEPS if args.quick else None)
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
        fewest = min(len(row.get("per_seed") or [0]) for row in results["tasks"].values())
        seeds = pages.Seeds(fewest, None if fewest >= pages.MIN_SEEDS else f"this run had --seeds {fewest}")
        for path in pages.update_results(tables, headline_markdown(results), out / "figures" if figures_drawn else None,
                                         seeds):
            print(f"updated {path}")


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _parser()
    args = parser.parse_args(argv)
    _check(parser, args)
    from hnn.sweeps import sweep
    out = args.out or hnn.tasks.repo_root() / ("results-quick" if args.quick else "results")
    tasks = args.tasks or (study.quick_tasks(hnn.tasks.paper_tasks()) if args.quick else hnn.tasks.paper_tasks())
    left_out = [task for task in hnn.tasks.paper_tasks() if task not in tasks] if args.quick and not args.tasks else []
    mode, steps = _mode(args)
    backend = "" if args.backend == "local" else f" --backend {args.backend}"
    print(f"reproduce: tasks {', '.join(tasks)}; {mode}; --jobs {args.jobs}{backend}; output {out}", flush=True)
    cuts = study.quick_cuts(tasks, steps, left_out) if args.quick else []
    if cuts:
        commands.say_quick("reproduce", cuts)
    pages.warn_stale(("headline", "results"))
    seeds = list(range(args.seed, args.seed + args.seeds))
    results = {"meta": {**_meta(args, argv, seeds, mode, steps), "quick_cuts": cuts}, "tasks": {},
               "seconds": {"tasks": {}}}
    start = time.perf_counter()
    rows = study.table_rows(tasks, args.quick, seeds)
    runs, jobs = sweep.reuse(study.plan(rows, seeds, out / "runs", steps, args.models))
    sweep.say_reused("reproduce", runs, jobs)
    jobs = plan.timed(jobs)
    results["meta"]["plan"] = plan.say("reproduce", study.stages(tasks, rows, plan.training(jobs, args.jobs), args.quick))
    trained, seconds = sweep.train_jobs(jobs, args.jobs, out / "logs", args.backend, args.ray_address, args.group,
                                        args.device)
    runs.update(trained)
    results["seconds"].update(seconds)
    tic = time.perf_counter()
    plotting.set_stamp(f"QUICK smoke run ({steps} steps per model): not the paper's settings" if args.quick else "")
    try:
        with torch_threads(1):      # as the training: two made the pixel evaluation 1.7x slower on a shared box
            study.evaluate_rows(rows, seeds, runs, results, None if args.no_figures else out / "figures", args.models,
                                study.QUICK_TRIALS if args.quick else None)
    finally:
        plotting.set_stamp("")
    results["seconds"]["evaluation"] = time.perf_counter() - tic
    results["seconds"]["total"] = time.perf_counter() - start
    write_outputs(results, out, args.update_docs, not args.no_figures)
    sweep.exit_if_failed(trained)
    return results


if __name__ == "__main__":
    main()
