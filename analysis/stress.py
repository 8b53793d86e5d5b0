"""The stress study: every kind on two scenes at the extremes of units, masses, horizons, step sizes
and precision; each cell works (within 2x of its nominal), degrades (its number) or stops (one error).

    python analysis/stress.py [--quick] [--out results/stress] [--update-docs]     # docs/stress.md

Scenes (the truth in closed form, states drawn at random, dx/dt exact):

- ``spring``: H = p^2 / (2 m) + k q^2 / 2 (m = k = 1), q ~ N(0, 1), p ~ N(0, 1);
- ``arm``: the two-link arm of ``experiment-arm`` (1 kg, 1 m links; q in radians, read as angles).

Each kind is fit to dx/dt by ``hnn.train`` at one small budget (``BUDGET``, the default ``--balance
auto`` of the runs: ``hnn.balance``), in the coordinates it reads: canonical [q, p] (hnn, baseline,
separable, dissipative, mechanical) or [q, qdot] (second_order). Its error is unit-free: the mean
over components of |f_j - f_true_j| / |f_true_j| on held-out states. Rows (``CELLS``):

- **units**: q, p or t in units 10^-3 or 10^3 times the scene's (q' = s q with p' = p / s, so
  Hamilton's equations hold with the same H; p' = s p with H' = s H, a mass unit; t' = s t with
  H' = H / s); **float64** training; **mass** ratio 10^3 (the spring's m / k, the arm's forearm
  against its upper arm);
- **units, --units on**: the nominal and each unit change again with ``hnn.units``' rescaling: scales
  s_q, s_p, s_t fit from the cell's training data (s_q = 1 for the arm's angles), the network trained
  in q / s_q, p / s_p, t / s_t and its field read back in the cell's units;
- **horizon** (spring): the nominal model rolled out by RK4 at dt = 0.1 for ``HORIZON`` steps, the
  true energy's largest relative change along it against the same over 1000 steps;
- **dt** (spring): RK4 at omega dt = 2.5 and 3.0 (its stability limit is 2.83) over 100 steps,
  the energy change against omega dt = 0.1's.

A cell **works** if its number is within 2x of the kind's nominal, **degrades** (its number and the
factor) otherwise, **stops** when training or the rollout raised (its error's first words); a
training that warned (data far from unit scale, ``hnn.training.UNIT_SCALE``) or a rollout that warned (dt past
RK4's stability limit on the model's fastest mode: ``hnn.integrators.stability``) is marked ``(warned)``.
The LNN (``lagrangian``) and the Cartesian kinds are not in the grid: the LNN's start is its own
part (``lnn_start``), the Cartesian kinds need a constraint graph these scenes do not have.
"""
from __future__ import annotations

import json
import os
import resource
import sys
import time
from pathlib import Path

import torch

import hnn
from hnn_analysis import commands, pages, plan
from hnn_analysis.extremes.lnn_start import lnn_start, lnn_start_text
from hnn_analysis.extremes.stress_grid import plan_stages, run
from hnn_analysis.extremes.stress_report import text
from hnn_analysis.provenance import provenance


def _seeds(results: dict) -> pages.Seeds:
    """The seeds behind the section's verdicts: the grid's cells are one fit each, the LNN's start its seeds."""
    if "lnn_start" in results:
        n = len({row["seed"] for row in results["lnn_start"]})
        return pages.Seeds(n, None if n >= pages.MIN_SEEDS else f"this run had --lnn-seeds {n}")
    return pages.Seeds(1, f"each cell is one fit (seed {results['seed']}) of a grid of {len(results['rows'])}; the "
                          "precision rows measure the spread over seeds 0, 1, 2 that a cell's factor of 2 must exceed")


def _report(path: Path, update_docs: bool) -> dict:
    """The tables of a saved ``stress.json`` or ``lnn-start.json``, printed and (``update_docs``) written."""
    results = json.loads(path.read_text())
    if "lnn_start" in results:
        steps = int(results["meta"]["command"].split("--lnn-steps")[1].split()[0]) if "--lnn-steps" in \
            results["meta"]["command"] else 0
        name, body = "lnn-start", lnn_start_text(results["lnn_start"], results["meta"], steps)
    else:
        name, body = "stress", text(results, results["meta"])
    print(body)
    if update_docs:
        print(f"updated the {name} section of {pages.update_section(name, body, _seeds(results))}")
    return results


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its finished workers."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def main(argv=None) -> dict:
    parser = hnn.cli.Parser(description=__doc__.split("\n")[0])
    commands.add_flags(parser, quick="two kinds, four cells, 150 steps, a 1000-step horizon, no precision part "
                                     "(under a minute)",
                       out="folder for stress.json and stress.md", out_default=Path("results/stress"),
                       update_docs="write the stress section of docs/stress.md")
    parser.add_argument("--seed", type=hnn.cli.int_at_least(0), default=0, help="seed of the data and the inits")
    parser.add_argument("--jobs", type=hnn.cli.int_at_least(1), default=2,
                        help="worker processes of the grid, one torch thread each (default 2: the default grid's "
                             "CPU time over two cores; the numbers do not depend on it)")
    parser.add_argument("--lnn-start", dest="lnn_start", action="store_true",
                        help="instead of the grid: the LNN's start on CHNN's chains at N = 1, 3, 5 (lnn-start section)")
    parser.add_argument("--lnn-seeds", dest="lnn_seeds", type=hnn.cli.int_at_least(1), default=5,
                        help="seeds of --lnn-start")
    parser.add_argument("--lnn-steps", dest="lnn_steps", type=hnn.cli.int_at_least(0), default=0,
                        help="training steps of --lnn-start after the first batch (0: none)")
    parser.add_argument("--report", type=Path, default=None,
                        help="measure nothing: rewrite the tables (and with --update-docs the section) from a "
                             "stress.json or lnn-start.json this command wrote, stamped with its own command and commit")
    args = parser.parse_args(argv)
    if args.report is not None:
        return _report(args.report, args.update_docs)
    torch.set_num_threads(1)
    meta = {**provenance(), "command": commands.portable_command(sys.argv[1:] if argv is None else list(argv),
                                                                 "analysis/stress.py")}
    tic, cpu = time.perf_counter(), _cpu_seconds()
    if args.lnn_start:
        results = {"lnn_start": lnn_start(seeds=args.lnn_seeds, steps=args.lnn_steps, save_dir=args.out / "chain")}
    else:
        plan.say("stress", plan_stages(args.quick, args.seed, args.jobs))
        results = run(args.quick, args.seed, args.jobs)
    meta["seconds"], meta["cpu_seconds"] = time.perf_counter() - tic, _cpu_seconds() - cpu
    meta["load"] = os.getloadavg()[0]
    meta["jobs"] = 1 if args.lnn_start else args.jobs
    results["meta"] = meta
    if args.lnn_start:
        body = lnn_start_text(results["lnn_start"], meta, args.lnn_steps)
        commands.publish(args.out, "lnn-start", results, body, {"lnn-start": body} if args.update_docs else {},
                         _seeds(results))
    else:
        body = text(results, meta)
        commands.publish(args.out, "stress", results, body, {"stress": body} if args.update_docs else {},
                         _seeds(results))
    return results


if __name__ == "__main__":
    main()
