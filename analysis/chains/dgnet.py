"""DGNet's protocol (Matsubara, Ishikawa & Yaguchi, NeurIPS 2020) on the spring, the pendulum, the
real pendulum and the 2-body task: their published rows beside ours, every row of theirs trained
here the same way (docs/dgnet.md).

    python analysis/chains/dgnet.py --quick                                       # a smoke run (QUICK)
    python analysis/chains/dgnet.py --steps 300 --seeds 2 --out results-dgnet    # a small budget
    python analysis/chains/dgnet.py --tasks spring pend --seeds 3 --jobs 2        # their steps (SETTINGS)
    python analysis/chains/dgnet.py --tasks pend --jobs 2 --update-docs   # their 15 trials: docs/dgnet.md, pend's
    python analysis/chains/dgnet.py --tasks 2body --jobs 2 --update-docs  # 2body's section (cost below)
    python analysis/chains/dgnet.py --tasks spring --seeds 15 --rows DGNet HNN --compare-init --jobs 2 --update-docs
                                     # their init against the original HNN's (dgnet_init), section dgnet-init-spring

The protocol, theirs and ours (where it differs), and the 2-body's cost: ``dgnet_protocol``'s docstring.
"""
from __future__ import annotations

import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import hnn
from hnn.sweeps import flags as sweep_flags, sweep
from hnn_analysis import commands, pages
from hnn_analysis.chains import dgnet_init
from hnn_analysis.chains.dgnet_protocol import (QUICK, QUICK_DATA, ROWS, SETTINGS, TASKS, TRIALS, PUBLISHED,
                                                measure_job, quick_cuts, rows_for, table, task_table)
from hnn_analysis.commands import portable_command
from hnn_analysis.provenance import provenance


def main(argv=None) -> dict:
    parser = hnn.cli.Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", choices=TASKS, default=list(TASKS), help="tasks to run")
    parser.add_argument("--init", choices=hnn.names.INITS, default="zero_bias",
                        help="how every row's MLPs start: zero_bias (theirs: orthogonal weights, zero biases) or "
                             "orthogonal (the original HNN's: torch's default biases)")
    parser.add_argument("--rows", nargs="+", choices=list(ROWS), default=None,
                        help="train these rows only (default: every row of each task); --update-docs then writes "
                             "the init comparison alone, never a task's table with rows missing")
    parser.add_argument("--compare-init", action="store_true",
                        help="train the rows from both inits (zero_bias, theirs; orthogonal, the original HNN's) and "
                             "compare them over the seeds (section dgnet-init-<task> of dgnet_init.TASKS)")
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
    if args.update_docs and args.rows and not args.compare_init:
        parser.error("--update-docs with --rows would write a task's table with rows missing; add --compare-init "
                     "(its own section) or drop --rows")
    if args.compare_init and args.update_docs and set(args.tasks) - set(dgnet_init.TASKS):
        parser.error(f"docs/dgnet.md has an init comparison for {', '.join(dgnet_init.TASKS)} only, not for every "
                     f"task of {args.tasks}: add the task to pages.DGNET_INIT_TASKS and its markers to the page")
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
    labels = {task: [label for label in rows_for(task) if args.rows is None or label in args.rows]
              for task in args.tasks}
    inits = dgnet_init.INITS if args.compare_init else (args.init,)
    work = [(task, label, seed, steps[task], args.out, init, args.quick, args.device or "cpu")
            for seed in range(args.seeds) for init in inits
            for task in args.tasks for label in labels[task]]
    done, progress = {}, sweep.Progress(len(work))
    print(f"{progress.tag()} training and measuring {len(work)} runs", flush=True)

    def record(i: int, key: tuple, result: dict) -> None:
        done[key] = result
        init = f" ({key[3]})" if args.compare_init else ""
        print(f"{progress.advance()} {key[0]} {key[1]} seed {key[2]}{init}: derivative {result['derivative']:.3g}, "
              f"energy {', '.join(f'{k} {v:.3g}' for k, v in result['energy'].items())}", flush=True)

    if args.jobs == 1:
        for i, job in enumerate(work, 1):
            record(i, *measure_job(job))
    else:
        with ProcessPoolExecutor(args.jobs) as pool:
            for i, (key, result) in enumerate(pool.map(measure_job, work), 1):
                record(i, key, result)
    rows = {task: {label: [done[(task, label, seed, inits[0])] for seed in range(args.seeds)] for label in labels[task]}
            for task in args.tasks}
    meta["seconds"] = time.perf_counter() - tic
    results = {"meta": {**meta, "quick": args.quick, "quick_cuts": cut}, "steps": steps, "seeds": args.seeds,
               "tasks": args.tasks, "init": list(inits) if args.compare_init else args.init,
               "published": PUBLISHED,
               "settings": {task: SETTINGS[task] for task in args.tasks}, "rows": rows}
    if args.compare_init:
        results["init_rows"] = {task: {label: {init: [done[(task, label, seed, init)] for seed in range(args.seeds)]
                                               for init in inits} for label in labels[task]} for task in args.tasks}
        text = "\n\n".join(dgnet_init.init_table(results, task) for task in args.tasks) + "\n"
        sections = {f"dgnet-init-{task}": dgnet_init.init_table(results, task) for task in args.tasks}
    else:
        text = table(results)
        sections = {f"dgnet-{task}": task_table(results, task) for task in args.tasks}
    sections = sections if args.update_docs else {}
    seeds = pages.Seeds(args.seeds, None if args.seeds >= pages.MIN_SEEDS
                                 else f"this run had --seeds {args.seeds} of their 15 trials")
    commands.publish(args.out, "dgnet-init" if args.compare_init else "dgnet", results, text, sections, seeds)
    return results


if __name__ == "__main__":
    main()
