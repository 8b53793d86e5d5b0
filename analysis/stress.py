"""The stress study: every kind on three scenes at the extremes of units, masses, horizons, step sizes and
precision; each cell works (within 2x of its nominal), degrades (its number) or stops (one error).

    python analysis/stress.py [--quick] [--out results/stress] [--update-docs]     # docs/stress.md
    python analysis/stress.py --scan [--update-docs]         # where --units auto starts (units-scan)
    python analysis/stress.py --lnn-pinv [--lnn-runs KEY ...] [--lnn-past N] [--update-docs]     # lnn-pinv

The grid, its scenes, cells and outcomes: ``hnn_analysis.extremes.stress_grid``. ``--scan``: the spring in
its own units with its states or its rates scaled over decades, the HNN and the mechanical kind over three
seeds: how a fit degrades with the data's sizes, and where auto's bounds lie. ``--lnn-pinv``: the LNN runs of
the peers' table that stopped with a singular d2L/dqdot2, trained again with the pseudo-inverse solve past
that step (``hnn_analysis.chains.lnn_pinv``); ``--lnn-start``: the LNN's first steps (``lnn_start``).
"""
from __future__ import annotations

import json
import os
import resource
import sys
import time
from pathlib import Path


import hnn
from hnn.threads import torch_threads
from hnn_analysis import commands, pages, plan
from hnn_analysis.chains.lnn_pinv import measure as lnn_pinv, pinv_results_text, pinv_seeds
from hnn_analysis.extremes.lnn_start import lnn_start, start_results_text, start_seeds
from hnn_analysis.extremes.stress_grid import BUDGET, plan_stages, run, scan
from hnn_analysis.extremes.stress_report import grid_seeds, grid_text, scan_results_text, scan_seeds
from hnn_analysis.provenance import provenance

# section -> (the key its results hold, their text, the seeds behind them)
SECTIONS = {"stress": ("rows", grid_text, grid_seeds), "units-scan": ("scan", scan_results_text, scan_seeds),
            "lnn-start": ("lnn_start", start_results_text, start_seeds),
            "lnn-pinv": ("lnn_pinv", pinv_results_text, pinv_seeds)}


def _measure(section: str, args, parser) -> dict:
    """The results of ``section``'s measurement (the grid, the scan, the LNN's start or its pseudo-inverse runs)."""
    if section == "units-scan":
        return {"scan": scan(BUDGET, args.jobs), "budget": BUDGET}
    if section == "lnn-start":
        return {"lnn_start": lnn_start(seeds=args.lnn_seeds, steps=args.lnn_steps, save_dir=args.out / "chain"),
                "steps": args.lnn_steps}
    if section == "lnn-pinv":
        try:
            return {"lnn_pinv": lnn_pinv(args.lnn_runs, args.lnn_past, args.out / "chain", args.jobs), "past": args.lnn_past}
        except ValueError as err:
            parser.error(str(err))
    plan.say("stress", plan_stages(args.quick, args.seed, args.jobs))
    return run(args.quick, args.seed, args.jobs)


def _publish(results: dict, out: Path | None, update_docs: bool) -> None:
    """Print the section of ``results`` and write it: under ``out`` (none for --report) and, with ``update_docs``, its page."""
    section = next(name for name, (key, *_) in SECTIONS.items() if key in results)
    _, text_of, seeds_of = SECTIONS[section]
    body = text_of(results)
    sections = {section: body} if update_docs else {}
    if out is not None:
        commands.publish(out, "stress" if section == "stress" else section, results, body, sections, seeds_of(results))
        return
    print(body)
    if update_docs:
        print(f"updated the {section} section of {pages.update_section(section, body, seeds_of(results))}")


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its finished workers."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


@torch_threads(1)       # one torch thread, the caller's count back after (tests call main in-process)
def main(argv=None) -> dict:
    parser = hnn.cli.Parser(description=__doc__.split("\n")[0])
    commands.add_flags(parser, quick="two kinds, five cells, 150 steps, a 1000-step horizon, one heavy seed, no precision "
                                     "part (under a minute)",
                       out="folder for the results' JSON and table", out_default=Path("results/stress"),
                       update_docs="write the section of docs/stress.md")
    parser.add_argument("--seed", type=hnn.settings.int_at_least(0), default=0, help="seed of the data and the inits")
    parser.add_argument("--jobs", type=hnn.settings.int_at_least(1), default=2,
                        help="worker processes, one torch thread each (default 2: the CPU time over two cores; the "
                             "numbers do not depend on it)")
    parser.add_argument("--scan", action="store_true",
                        help="instead of the grid: the spring fit in its own units with its states or its rates "
                             "scaled, where --units auto starts (units-scan section)")
    parser.add_argument("--lnn-start", dest="lnn_start", action="store_true",
                        help="instead of the grid: the LNN's start on CHNN's chains at N = 1, 3, 5 (lnn-start section)")
    parser.add_argument("--lnn-seeds", dest="lnn_seeds", type=hnn.settings.int_at_least(1), default=5,
                        help="seeds of --lnn-start")
    parser.add_argument("--lnn-steps", dest="lnn_steps", type=hnn.settings.int_at_least(0), default=0,
                        help="training steps of --lnn-start after the first batch (0: none)")
    parser.add_argument("--lnn-pinv", dest="lnn_pinv", action="store_true",
                        help="instead of the grid: the peers' LNN runs that stopped with a singular d2L/dqdot2 "
                             "(docs/peers-runs.json), trained again with --lnn_solve pinv past that step (lnn-pinv "
                             "section)")
    parser.add_argument("--lnn-past", dest="lnn_past", type=hnn.settings.int_at_least(1), default=500,
                        help="steps of --lnn-pinv past the step where each run stopped")
    parser.add_argument("--lnn-runs", dest="lnn_runs", nargs="+", default=None, metavar="KEY",
                        help="--lnn-pinv's runs (e.g. chain5/lagrangian/seed1; default: every one that stopped)")
    parser.add_argument("--report", type=Path, default=None,
                        help="measure nothing: rewrite the tables (and with --update-docs the section) from a JSON "
                             "this command wrote, stamped with its own command and commit")
    args = parser.parse_args(argv)
    if args.report is not None:
        results = json.loads(args.report.read_text())
        _publish(results, None, args.update_docs)
        return results
    section = "units-scan" if args.scan else "lnn-start" if args.lnn_start else "lnn-pinv" if args.lnn_pinv else "stress"
    meta = {**provenance(), "command": commands.portable_command(sys.argv[1:] if argv is None else list(argv),
                                                                 "analysis/stress.py")}
    tic, cpu = time.perf_counter(), _cpu_seconds()
    results = _measure(section, args, parser)
    meta["seconds"], meta["cpu_seconds"] = time.perf_counter() - tic, _cpu_seconds() - cpu
    meta["load"], meta["jobs"] = os.getloadavg()[0], 1 if args.lnn_start else args.jobs
    results["meta"] = meta
    _publish(results, args.out, args.update_docs)
    return results


if __name__ == "__main__":
    main()
