"""Fitted on a few, run on many: the pair kind fitted on a chain of 8 springs, rolled out on chains of N = 8 ... 4096.

    python analysis/bodies.py --quick                     # N = 8 ... 256, library and sampled fits (about a minute)
    python analysis/bodies.py --update-docs               # N = 8 ... 4096, and Adam; docs/bodies.md's section

The pair kind (``--model pairwise``) is fitted once on the lattice task's data (experiment-lattice: 8 bodies,
the default dataset of ``--seed``) by each of ``--fits``: ``library`` (the radial library, one solve),
``swim`` (sampled radial neurons, one solve) and ``adam`` (an MLP of (r, 1/r) by Adam, ``--adam-steps`` steps of
batch 200). The same model, unchanged, then rolls out chains of each N of ``--sizes`` from ``--starts`` start
states of the task's start law, by leapfrog at step ``--dt`` over ``--horizon``, float64. Beside it, the same
leapfrog on the true forces (``experiment-lattice/data.py``, O(N)), and the reference: DOP853 at rtol 1e-10.

Per N and fit:
- **energy error per body**: max over t of |H(x(t)) - H(x(0))| / N along the model's path, H the true energy
  (mean over the starts); the same for the true-force leapfrog;
- **rollout error**: |x(T) - x_ref(T)| / |x_ref(T)| at the horizon (mean over the starts), both integrators;
- **seconds per step**: the median of ``REPEATS`` timed leapfrog rollouts of ``TIMED_STEPS`` steps of all
  starts at once, divided by the steps, for the model and for the true forces, measured in one process.

Prints a table, writes ``bodies.json`` and ``bodies.md`` under ``--out``, and with ``--update-docs`` the
``bodies`` section of docs/bodies.md. Numbers come from this command, never typed by hand.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hnn_analysis.commands import add_flags, portable_command, publish
from hnn_analysis.provenance import provenance
from hnn_analysis.scenes.bodies_study import FITS, FULL_SIZES, QUICK_FITS, QUICK_SIZES, study, table


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    add_flags(p, quick=f"N = {', '.join(map(str, QUICK_SIZES))} and the least-squares fits only (no Adam)",
              out="folder for bodies.json and bodies.md", out_default=Path("results/bodies"),
              update_docs="write the bodies section of docs/bodies.md")
    p.add_argument("--sizes", type=int, nargs="+", help=f"chain lengths N (default {FULL_SIZES}; --quick {QUICK_SIZES})")
    p.add_argument("--fits", nargs="+", choices=FITS, help=f"how the pair kind is fitted (default {FITS}; --quick "
                                                          f"{QUICK_FITS})")
    p.add_argument("--seed", type=int, default=0, help="the training data's seed and the fits' (default 0)")
    p.add_argument("--starts", type=int, default=4, help="start states per N (default 4)")
    p.add_argument("--dt", type=float, default=0.05, help="the leapfrog's step (default 0.05)")
    p.add_argument("--horizon", type=float, default=10.0, help="the rollouts' length in time units (default 10)")
    p.add_argument("--adam-steps", dest="adam_steps", type=int, default=2000, help="Adam's steps (default 2000)")
    p.add_argument("--hidden-dim", dest="hidden_dim", type=int, default=64,
                   help="the MLP's width (adam) and the sampled neurons (swim) (default 64)")
    args = p.parse_args(argv)
    sizes = tuple(args.sizes or (QUICK_SIZES if args.quick else FULL_SIZES))
    fits = tuple(args.fits or (QUICK_FITS if args.quick else FITS))
    for value, name in ((args.starts, "--starts"), (args.dt, "--dt"), (args.horizon, "--horizon")):
        if not value > 0:
            raise SystemExit(f"{name} {value}: must be > 0")
    if min(sizes) < 2:
        raise SystemExit(f"--sizes {min(sizes)}: a chain needs at least 2 bodies")
    results = study(sizes, fits, args.seed, args.starts, args.dt, args.horizon, args.adam_steps, args.hidden_dim)
    results["meta"] = {**provenance(), "command": portable_command(list(sys.argv[1:] if argv is None else argv),
                                                                    "analysis/bodies.py")}
    text = table(results)
    publish(args.out, "bodies", results, text, {"bodies": text} if args.update_docs else None)
    return results


if __name__ == "__main__":
    main()
