"""The least-squares fits on the paper's tasks and the chain: the sampled fit and the library beside the
paper's Adam-trained HNN and baseline and beside pysindy's SINDy, over seeds.

    python analysis/fits/fit_tasks.py --jobs 2                  # spring pend real 2body 3body chain, 5 seeds
    python analysis/fits/fit_tasks.py --quick                   # spring and pend, one seed, 100 Adam steps
    python analysis/fits/fit_tasks.py --jobs 2 --update-docs    # docs/fits.md, sections fits-tasks, fits-library
    python analysis/fits/fit_tasks.py --from-json results/fit_tasks.json --update-docs   # the tables again, nothing run

Every rung of ``task_fits.RUNGS`` that a task takes (the pair kind's three on the tasks that declare their
bodies, 2body and 3body) trains at every seed in one sweep (``--jobs`` processes;
runs saved before with the same args, by this command, reproduce.py or the scene study, are reused), then
each is measured (``task_fits.measure``): its test loss, the energy MSE of the task's protocols and its
training seconds on one thread. Writes ``<out>/fit_tasks.json`` and ``.md``. Pixels: not a rung; its
latent coordinates are learned by the autoencoder, which no linear solve finds.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import hnn
from hnn.sweeps import sweep
from hnn_analysis import commands, pages
from hnn_analysis.fits import task_fits
from hnn_analysis.provenance import provenance


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    p = hnn.cli.Parser(prog="fit_tasks.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", choices=task_fits.TASKS, default=None, help="tasks (default: all)")
    commands.add_flags(p, quick="spring and pend, one seed, 100 Adam steps, 5 trials of each energy protocol",
                       out="output folder (default results/ or results-quick/; runs in <out>/runs)",
                       seeds="seeds of every rung (default 5)", seeds_default=5,
                       jobs="training processes (one thread each past one)",
                       update_docs="write docs/fits.md's sections fits-tasks and fits-library (full settings only)")
    p.add_argument("--from-json", type=Path, default=None, metavar="FILE",
                   help="write the tables of a saved fit_tasks.json (its own command and commit), training and "
                        "measuring nothing")
    args = p.parse_args(argv)
    if args.update_docs and args.quick:
        p.error("--update-docs writes full-settings results into docs/fits.md; drop --quick")
    if args.from_json is not None:
        if not args.from_json.is_file():
            p.error(f"--from-json {args.from_json}: no such file; give the fit_tasks.json a full run wrote in its --out")
        results = json.loads(args.from_json.read_text())
        if args.update_docs and results["meta"]["quick"]:
            p.error(f"--from-json {args.from_json} holds a --quick run; --update-docs takes full-settings results")
        return _publish(results, args.from_json.parent, args.update_docs)
    tasks = args.tasks or (["spring", "pend"] if args.quick else list(task_fits.TASKS))
    seeds = list(range(1 if args.quick else args.seeds))
    out = args.out or hnn.tasks.repo_root() / ("results-quick" if args.quick else "results")
    tic = time.perf_counter()
    runs, todo = sweep.reuse(task_fits.plan(tasks, seeds, out / "runs", args.quick))
    print(f"fit_tasks: {len(runs)} runs reused, {len(todo)} to train", flush=True)
    trained, _ = sweep.train_jobs(todo, args.jobs, out / "logs")
    runs.update(trained)
    results = {"meta": {**provenance(), "seeds": seeds, "quick": args.quick,
                        "command": commands.portable_command(argv, "analysis/fits/fit_tasks.py")},
               "tasks": {}, "seconds": {"training": time.perf_counter() - tic}}
    tic = time.perf_counter()
    for task in tasks:
        by_seed = {seed: {label: runs[key] for label in task_fits.rungs(task)
                          if isinstance(runs.get(key := f"{task}/{label}/seed{seed}"), Path)} for seed in seeds}
        results["tasks"][task] = task_fits.measure(task, by_seed, args.quick)
        print(f"  {task} measured", flush=True)
    results["seconds"]["measure"] = time.perf_counter() - tic
    _publish(results, out, args.update_docs)
    sweep.exit_if_failed(runs)
    return results


def _publish(results: dict, out: Path, update_docs: bool) -> dict:
    """Write ``<out>/fit_tasks.json`` and ``.md`` and, with ``update_docs``, docs/fits.md's two sections."""
    text = task_fits.markdown(results)
    sections = {}
    if update_docs:
        head = text.split("\n\n**Fits beside Adam**")[0] + "\n\n"
        sections = {"fits-tasks": head + "\n".join(task_fits.accuracy_table(results)) + "\n",
                    "fits-library": head + "\n".join(task_fits.library_table(results)) + "\n"}
    seeds = len(results["meta"]["seeds"])
    commands.publish(out, "fit_tasks", results, text, sections,
                     pages.Seeds(seeds, None if seeds >= pages.MIN_SEEDS else "a --seeds run below 3"))
    return results


if __name__ == "__main__":
    main()
