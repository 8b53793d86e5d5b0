"""What a second torch thread buys a training run of each task's default (paper) size.

    python analysis/benchmarks/threads.py                          # spring, 2body, chain: 100 steps, 3 rounds
    python analysis/benchmarks/threads.py --tasks spring,pixels --steps 50 --repeats 5
    python analysis/benchmarks/threads.py --update-docs            # docs/speed.md's section "threads"

Each round trains every task's default model and data for ``--steps`` optimizer steps at each
thread count of ``--threads`` (``hnn.threads.torch_threads`` in this process, interleaved: 1, 2, 1, 2,
...), each with the round's seed, and reads the training loop's seconds (``train_seconds`` of
``metrics.json``; the dataset is built once per task, untimed). Beside each run, the cores other
processes kept busy meanwhile (``provenance.others_load``): a second thread pays only where a second
core is free, so the same command measures a quiet box and a shared one differently, and the table
says which it saw. Prints a Markdown table (median seconds per 100 steps, their range, the ratio of
the medians, the others' load) and writes JSON to ``--out``; ``--update-docs`` writes the table into
docs/speed.md.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path


import hnn
from hnn.io import write_json
from hnn.threads import torch_threads
from hnn_analysis import pages
from hnn_analysis.provenance import cpu_snapshot, machine, others_load, provenance


def _time(task: str, threads: int, steps: int, seed: int, dataset: dict, save_dir: Path) -> dict:
    """One run of ``task``'s defaults for ``steps`` steps at ``threads`` threads: its loop's seconds and the load."""
    config = hnn.tasks.task_config(task, {"total_steps": steps, "seed": seed, "threads": threads,
                                          "save_dir": str(save_dir / f"t{threads}")})
    with torch_threads(threads):        # the count timed, the caller's back after
        start = cpu_snapshot()
        run = hnn.run_experiment(config, dataset)
        others = others_load(start, cpu_snapshot())
    metrics = json.loads((run / "metrics.json").read_text())
    return {"threads": threads, "seed": seed, "seconds": metrics["train_seconds"], "others": others,
            "loadavg": os.getloadavg()[0]}


def main(argv=None) -> dict:
    p = hnn.cli.Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", default="spring,2body,chain", help="comma-separated tasks (their default sizes)")
    p.add_argument("--steps", type=hnn.settings.int_at_least(1), default=100, help="optimizer steps a run")
    p.add_argument("--repeats", type=hnn.settings.int_at_least(1), default=3, help="interleaved rounds")
    p.add_argument("--threads", default="1,2", help="comma-separated thread counts")
    p.add_argument("--out", type=Path, default=Path("results/threads.json"))
    p.add_argument("--update-docs", action="store_true", help="write the table into docs/speed.md")
    args = p.parse_args(argv)
    tasks = [t for t in args.tasks.split(",") if t]
    unknown = set(tasks) - set(hnn.available_tasks())
    if unknown:
        p.error(f"--tasks {','.join(sorted(unknown))}: no such task; choose from {', '.join(hnn.available_tasks())}")
    counts = [hnn.settings.int_at_least(1)(t) for t in args.threads.split(",")]
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        data = {task: hnn.tasks.task_config(task, {"seed": 0}).dataset() for task in tasks}
        for seed in range(args.repeats):
            for task in tasks:
                for threads in counts:
                    row = _time(task, threads, args.steps, seed, data[task], Path(tmp) / task)
                    runs.setdefault(task, []).append(row)
                    print(f"  round {seed} {task:8s} {threads} thread(s): {row['seconds']:.2f} s (other processes "
                          f"kept {row['others']:.2f} cores busy)", flush=True)
    meta = provenance()
    given = list(argv if argv is not None else sys.argv[1:])
    if "--out" in given:            # where the JSON went is no part of the measurement (and may be a machine's path)
        del given[given.index("--out"):given.index("--out") + 2]
    command = " ".join(["python analysis/benchmarks/threads.py", *given])
    lines = [pages.generated_by({**meta, "command": command.strip()}, f"{machine(meta)}, torch {meta['torch']}")
             + f": each task's default model and data, {args.steps} optimizer steps a run, "
             f"{args.repeats} interleaved rounds; seconds per 100 steps, median (range); others: the cores other "
             "processes kept busy during the runs (min-max)", "",
             "| task | " + " | ".join(f"{t} thread(s)" for t in counts) + " | "
             + " | ".join(f"{t} / {counts[0]}" for t in counts[1:]) + " | others |",
             "| --- | " + "---: | " * (2 * len(counts) - 1) + "--- |"]
    summary = {}
    for task, rows in runs.items():
        per = {t: [100 * r["seconds"] / args.steps for r in rows if r["threads"] == t] for t in counts}
        med = {t: statistics.median(v) for t, v in per.items()}
        loads = [r["others"] for r in rows]
        summary[task] = {"median_s_per_100_steps": med, "ratio": {t: med[t] / med[counts[0]] for t in counts[1:]},
                         "load": [min(loads), max(loads)]}
        lines.append(f"| {task} | " + " | ".join(f"{med[t]:.3g} ({min(per[t]):.3g}-{max(per[t]):.3g})" for t in counts)
                     + " | " + " | ".join(f"{med[t] / med[counts[0]]:.2f}" for t in counts[1:])
                     + f" | {min(loads):.1f}-{max(loads):.1f} |")
    table = "\n".join(lines)
    print(table)
    result = {"meta": {**meta, "command": command, "steps": args.steps, "repeats": args.repeats},
              "runs": runs, "summary": summary, "table": table}
    write_json(args.out, result)
    print(f"wrote {args.out}")
    if args.update_docs:
        print(f"updated {pages.update_section('threads', table)}")
    return result


if __name__ == "__main__":
    main()
