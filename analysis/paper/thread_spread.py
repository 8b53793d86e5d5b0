"""How far the paper tables' numbers move between one torch thread and two, against how far they move
between seeds: the spread a table's seeds must cover (docs/testing.md, section ``thread-spread``).

    python analysis/paper/thread_spread.py                       # spring, pend, real, 2body; seeds 0-2
    python analysis/paper/thread_spread.py --tasks spring --seeds 2 --out results/thread-spread
    python analysis/paper/thread_spread.py --update-docs         # docs/testing.md

Each task's paper runs (baseline and HNN, full settings) train at every seed once at one thread and
once at two (``hnn.threads.torch_threads`` in this process; each count's runs in their own folder under
``--out``, since the thread count is not part of a run's identity), one run at a time. Float32 sums
in other orders at two threads, so the same seed ends on other weights; the table puts that gap (the
largest ratio between the thread counts at one seed) beside the ratio of the largest to the smallest
seed at one thread, for the test loss and the energy MSE of both protocols (``registry``'s
evaluation, the same as ``reproduce.py``'s).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path


import hnn
from hnn.sweeps import sweep
from hnn.threads import torch_threads
from hnn_analysis import commands
from hnn_analysis.pages import generated_by
from hnn_analysis.paper import study
from hnn_analysis.provenance import machine, provenance

TASKS = ("spring", "pend", "real", "2body")
THREADS = (1, 2)
NUMBERS = ("test_loss", "energy_mse_paper", "energy_mse_corrected")


def _rows(tasks: list[str]) -> list[dict]:
    return [row for row in study.table_rows(tasks, quick=False) if row["note"] is None]


def measure(tasks: list[str], seeds: list[int], out: Path) -> dict:
    """``{task: {kind: {number: {threads: [value per seed]}}}}``, training what ``out`` lacks."""
    rows, found = _rows(tasks), {}
    for threads in THREADS:
        jobs = study.plan(rows, seeds, out / f"threads{threads}", None)
        runs, todo = sweep.reuse(jobs)
        progress = sweep.Progress(len(todo))
        # in this process, one run at a time: hnn.sweeps.sweep's in-process runs take one thread by design
        with torch_threads(threads):
            for job in todo:
                runs[job.key] = hnn.run_experiment(job.config)
                progress.advance()
                print(f"  {progress.tag()} {job.key} trained at {threads} thread(s)", flush=True)
        for row in rows:
            keys = [{kind: runs[f"{row['row']}/{kind}/seed{seed}"] for kind in study.row_models(row["task"])}
                    for seed in seeds]
            for seed_row in study.evaluate_seeds(row["task"], keys, None):
                for kind in study.row_models(row["task"]):
                    for number in NUMBERS:
                        value = seed_row[kind].get(number)
                        if value is not None:
                            (found.setdefault(row["task"], {}).setdefault(kind, {}).setdefault(number, {})
                             .setdefault(str(threads), []).append(value[0]))
    return found


def _gap(by_threads: dict) -> float:
    """The largest ratio between the thread counts' values at one seed."""
    one, two = by_threads["1"], by_threads["2"]
    return max(max(a, b) / min(a, b) for a, b in zip(one, two))


def markdown(results: dict) -> str:
    meta = results["meta"]
    lines = [generated_by(meta, machine(meta)) + f", {meta['seconds']:.0f} s: "
             f"the paper's runs of {', '.join(results['tasks'])} at full settings, seeds "
             f"{', '.join(map(str, results['seeds']))}, each trained at one torch thread and at two. "
             "Thread gap: the largest ratio between one and two threads at one seed; seed spread: the largest "
             "over the smallest seed at one thread.", "",
             "| task | model | number | 1 thread, per seed | 2 threads, per seed | thread gap | seed spread |",
             "| --- | --- | --- | --- | --- | ---: | ---: |"]
    gaps = []
    for task, kinds in results["numbers"].items():
        for kind, numbers in kinds.items():
            for number, by_threads in numbers.items():
                one, two = by_threads["1"], by_threads["2"]
                gap, spread = _gap(by_threads), max(one) / min(one)
                gaps.append((gap / spread, task, kind, number))
                lines.append(f"| {task} | {kind} | {number} | {', '.join(f'{v:.3g}' for v in one)} | "
                             f"{', '.join(f'{v:.3g}' for v in two)} | {gap:.3g}x | {spread:.3g}x |")
    within = sum(1 for ratio, *_ in gaps if ratio <= 1)
    widest = max(gaps)
    lines += ["", f"In {within} of {len(gaps)} rows the thread gap is within the seed spread; the widest against its "
                  f"spread: {widest[1]} {widest[2]} {widest[3]} ({widest[0]:.2g}x its seed spread)."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = hnn.cli.Parser(description=__doc__.split("\n")[0])
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=hnn.tasks.paper_tasks())
    commands.add_flags(parser, seeds="seeds 0 .. N-1 of every run", seeds_default=3,
                       out="folder for the runs, thread_spread.json and thread_spread.md",
                       out_default=Path("results/thread-spread"),
                       update_docs="write the thread-spread section of docs/testing.md")
    args = parser.parse_args(argv)
    tic = time.perf_counter()
    numbers = measure(args.tasks, list(range(args.seeds)), args.out)
    meta = {**provenance(), "command": commands.portable_command(argv, "analysis/paper/thread_spread.py"),
            "seconds": time.perf_counter() - tic}
    results = {"meta": meta, "tasks": args.tasks, "seeds": list(range(args.seeds)), "numbers": numbers}
    text = markdown(results)
    commands.publish(args.out, "thread_spread", results, text, {"thread-spread": text} if args.update_docs else {})
    return results


if __name__ == "__main__":
    main()
