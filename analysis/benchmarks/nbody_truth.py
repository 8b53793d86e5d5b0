"""The gravity task's truth at large N: our true forces' integrators against REBOUND's, cost and accuracy against N.

    python analysis/benchmarks/nbody_truth.py --quick            # N = 8, 64, 512 (under a minute)
    python analysis/benchmarks/nbody_truth.py --update-docs      # N = 8 ... 4096; docs/bodies.md, section bodies-rebound

One start state of the gravity task (experiment-gravity: N unit masses in a rotating disk at the training's density,
Plummer-softened by ``--softening``, G = 1) per N, drawn from ``--seed`` as ``analysis/bodies.py`` draws its starts,
integrated to ``--horizon`` by each of ``METHODS``, float64, one thread:

- our true forces (``hnn.orbits.nbody``: every pair, in blocks past 64 bodies) stepped by ``hnn.rollout``'s
  ``leapfrog`` (kick-drift-kick, one force evaluation a step) and ``yoshida4`` (three), as ``analysis/bodies.py``
  steps them, at ``--dt``;
- REBOUND (``hnn.orbits.rebound_truth``, the ``nbody`` extra: direct summation in C, every ordered pair) by its
  ``leapfrog`` (drift-kick-drift) and ``WHFast`` (Wisdom-Holman in Jacobi coordinates) at the same ``--dt``, and
  ``IAS15`` (15th order, adaptive: its own steps, counted), which is the reference: its energy error is round-off's.

Per N and method:
- **ms per step**: the fixed-step methods: the median of ``--repeats`` timed runs of a few steps (the methods
  alternated run by run, so load hits all alike), divided by the steps; ours times the whole ``hnn.rollout`` call
  (its first kick's extra force evaluation included), REBOUND's its stepping (adding the particles is not a step).
  IAS15: the median over the horizon's output intervals of the interval's seconds over its steps;
- **energy error per body**: max over the outputs (every ``--dt``) of |H(t) - H(0)| / N, H the softened energy;
- **error at T**: |x(T) - x_IAS15(T)| / |x_IAS15(T)|;
- **the floor**: one force evaluation's arithmetic, N(N - 1)/2 pairs of ``FLOPS_PER_PAIR`` operations (each pair
  once, its square root counted as one operation), at the rate a float64 matrix product reaches on one thread in
  this process: no direct-summation step can beat it, and a leapfrog step evaluates the forces once.

Prints the tables, writes ``nbody_truth.json`` and ``.md`` under ``--out``, and with ``--update-docs`` the
``bodies-rebound`` section of docs/bodies.md.
"""
from __future__ import annotations

import argparse
import sys

import hnn
from hnn.orbits import rebound_truth
from hnn.threads import torch_threads
from hnn_analysis.benchmarks.nbody_truth_measure import FULL_SIZES, METHODS, QUICK_SIZES, measure, table
from hnn_analysis.commands import add_flags, portable_command, publish
from hnn_analysis.provenance import provenance

__all__ = ["METHODS", "main"]


@torch_threads(1)       # one torch thread, the caller's count back after (tests call main in-process)
def main(argv=None) -> dict:
    p = hnn.cli.Parser(prog="nbody_truth.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_flags(p, quick=f"N = {', '.join(map(str, QUICK_SIZES))} (under a minute)",
              out="folder for nbody_truth.json and nbody_truth.md",
              out_default=hnn.tasks.repo_root() / "results" / "speed",
              update_docs="write the bodies-rebound section of docs/bodies.md")
    p.add_argument("--sizes", type=hnn.settings.int_at_least(2), nargs="+",
                   help=f"body counts N (default {FULL_SIZES}; --quick {QUICK_SIZES})")
    p.add_argument("--seed", type=int, default=0, help="the start states' seed, as analysis/bodies.py's (default 0)")
    p.add_argument("--dt", type=float, default=0.01, help="the fixed-step methods' step (default 0.01, bodies.py's)")
    p.add_argument("--horizon", type=float, default=0.05,
                   help="time of the runs (default 0.05, five steps: IAS15 takes about 15 steps of seconds each at "
                        "N = 4096, a step of its 15th-order Gauss-Radau at every body's pairs a dozen times)")
    p.add_argument("--repeats", type=hnn.settings.int_at_least(1), default=3, help="timed runs per method (default 3)")
    p.add_argument("--softening", type=float, default=None,
                   help="the Plummer length (default the gravity task's, experiment-gravity's SOFTENING)")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    argv = list(sys.argv[1:] if argv is None else argv)
    if args.update_docs and args.quick:
        raise SystemExit("--update-docs writes N up to 4096 into docs/bodies.md; drop --quick")
    for value, name in ((args.dt, "--dt"), (args.horizon, "--horizon")):
        if not value > 0:
            raise SystemExit(f"{name} {value}: must be > 0")
    if abs(args.horizon / args.dt - round(args.horizon / args.dt)) > 1e-9 * args.horizon / args.dt:
        raise SystemExit(f"--horizon {args.horizon} is not a whole number of steps of --dt {args.dt}: give one that is")
    softening = hnn.load_task("gravity").SOFTENING if args.softening is None else args.softening
    if not softening >= 0:
        raise SystemExit(f"--softening {softening}: must be >= 0 (0 is Newton's)")
    rebound_truth.rebound()                                  # the extra's ImportError before any measurement
    sizes = tuple(args.sizes or (QUICK_SIZES if args.quick else FULL_SIZES))
    results = measure(sizes, args.seed, args.dt, args.horizon, args.repeats, softening)
    results["meta"] = {**provenance(), "command": portable_command(argv, "analysis/benchmarks/nbody_truth.py")}
    text = table(results)
    publish(args.out, "nbody_truth", results, text, {"bodies-rebound": text} if args.update_docs else None)
    return results


if __name__ == "__main__":
    main()
