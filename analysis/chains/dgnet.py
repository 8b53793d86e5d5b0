"""DGNet's protocol (Matsubara, Ishikawa & Yaguchi, NeurIPS 2020) on the spring, the pendulum, the
real pendulum and the 2-body task: their published rows beside ours, every row of theirs trained
here the same way (docs/dgnet.md).

    python analysis/chains/dgnet.py --quick                                       # a smoke run (QUICK)
    python analysis/chains/dgnet.py --steps 300 --seeds 2 --out results-dgnet    # a small budget
    python analysis/chains/dgnet.py --tasks spring pend --seeds 3 --jobs 2        # their steps (SETTINGS)
    python analysis/chains/dgnet.py --tasks pend --seeds 3 --jobs 2 --update-docs  # docs/dgnet.md, pend's section
    python analysis/chains/dgnet.py --tasks 2body --seeds 3 --jobs 2 --update-docs # 2body's (cost below)

The protocol, theirs and ours (where it differs), and the 2-body's cost: ``dgnet_protocol``'s docstring.
"""
from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import hnn
from hnn import sweep, sweep_flags
from hnn_analysis import commands, pages
from hnn_analysis.chains.dgnet_protocol import (QUICK, QUICK_DATA, SETTINGS, TASKS, TRIALS, PUBLISHED, measure_job,
                                                quick_cuts, rows_for, table, task_table)
from hnn_analysis.commands import portable_command
from hnn_analysis.provenance import provenance


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", choices=TASKS, default=list(TASKS), help="tasks to run")
    parser.add_argument("--init", choices=hnn.names.INITS, default="zero_bias",
                        help="how every row's MLPs start: zero_bias (theirs: orthogonal weights, zero biases) or "
                             "orthogonal (the original HNN's: torch's default biases)")
    parser.add_argument("--steps", type=int, default=None,
                        help="optimizer steps per run (default: theirs, 2000; 2body 10000)")
    commands.add_flags(parser, quick=f"a smoke run of every task and row: {QUICK['seeds']} seed, {QUICK['steps']} steps a "
                       f"run (unless --seeds, --steps say otherwise), {QUICK_DATA['trajectories']} ring paths, "
                       f"{QUICK_DATA['orbits']} 2-body orbits, output in results-quick/dgnet; "
                       + commands.budget_words("dgnet"),
                       seeds="seeds 0..seeds-1 (theirs: 15 trials; --quick: 1)", seeds_default=None,
                       jobs="worker processes, one torch thread each",
                       out="folder for runs, json, table (default results-dgnet, or results-quick/dgnet with --quick)",
                       update_docs="write each task's table into its section of docs/dgnet.md (the other tasks' stay)")
    sweep_flags.add_device_flag(parser)
    args = parser.parse_args(argv)
    argv = sys.argv[1:] if argv is None else list(argv)
    if args.update_docs and args.quick:
        parser.error("--update-docs writes full-settings results into docs/dgnet.md; drop --quick")
    cut = quick_cuts(args.tasks, args.seeds, args.steps) if args.quick else []
    if args.quick:
        args.seeds, args.steps = args.seeds or QUICK["seeds"], args.steps or QUICK["steps"]
        commands.say_quick("dgnet", cut)
    args.seeds = args.seeds or TRIALS
    args.out = args.out or (hnn.tasks.repo_root() / "results-quick" / "dgnet" if args.quick else Path("results-dgnet"))
    tic, meta = time.perf_counter(), {**provenance(), "command": portable_command(argv, "analysis/chains/dgnet.py")}
    if args.steps is not None and args.steps < 1:
        sys.exit(f"error: --steps must be positive, got {args.steps}")
    steps = {task: SETTINGS[task]["steps"] if args.steps is None else args.steps for task in args.tasks}
    work = [(task, label, seed, steps[task], args.out, args.init, args.quick, args.device or "cpu")
            for seed in range(args.seeds)
            for task in args.tasks for label in rows_for(task)]
    done, progress = {}, sweep.Progress(len(work))
    print(f"{progress.tag()} training and measuring {len(work)} runs", flush=True)

    def record(i: int, key: tuple, result: dict) -> None:
        done[key] = result
        print(f"{progress.advance()} {key[0]} {key[1]} seed {key[2]}: derivative {result['derivative']:.3g}, "
              f"energy {', '.join(f'{k} {v:.3g}' for k, v in result['energy'].items())}", flush=True)

    if args.jobs == 1:
        for i, job in enumerate(work, 1):
            record(i, *measure_job(job))
    else:
        with ProcessPoolExecutor(args.jobs) as pool:
            for i, (key, result) in enumerate(pool.map(measure_job, work), 1):
                record(i, key, result)
    rows = {task: {label: [done[(task, label, seed)] for seed in range(args.seeds)] for label in rows_for(task)}
            for task in args.tasks}
    meta["seconds"] = time.perf_counter() - tic
    results = {"meta": {**meta, "quick": args.quick, "quick_cuts": cut}, "steps": steps, "seeds": args.seeds,
               "tasks": args.tasks, "init": args.init,
               "published": PUBLISHED,
               "settings": {task: SETTINGS[task] for task in args.tasks}, "rows": rows}
    text = table(results)
    sections = {f"dgnet-{task}": task_table(results, task) for task in args.tasks} if args.update_docs else {}
    seeds = pages.Seeds(args.seeds, None if args.seeds >= pages.MIN_SEEDS
                                 else f"this run had --seeds {args.seeds} of their 15 trials")
    commands.publish(args.out, "dgnet", results, text, sections, seeds)
    return results


if __name__ == "__main__":
    main()
