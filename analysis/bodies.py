"""Fitted on a few, run on many: the pair kind fitted on a chain of 8 springs, rolled out on chains of N = 8 ... 4096;
and, with ``--paper``, the pair kind on the paper's 2-body and 3-body protocols over seeds.

    python analysis/bodies.py --quick                     # N = 8 ... 256, library, sampled fit, its table (1 min)
    python analysis/bodies.py --update-docs               # N = 8 ... 4096, and Adam; docs/bodies.md's section
    python analysis/bodies.py --scene gravity --update-docs   # the same on softened gravity to N = 4096 (about 20
                                                              # minutes, one thread); section bodies-gravity
    python analysis/bodies.py --scene lj --update-docs    # the Lennard-Jones cluster cut off at 2.5, to N = 4096 in
                                                          # O(N) (about 6 minutes, one thread); section bodies-lj
    python analysis/bodies.py --paper --seeds 5 --jobs 2 --update-docs   # the protocols; section bodies-paper
    python analysis/bodies.py --paper --quick             # one seed, 60 Adam steps: a smoke run
    python analysis/bodies.py --scene gravity --sizes 8 64 512 4096 --backend ray --ray-address HEAD:6379
                                                          # each N a Ray task on a cluster (every fit at every N)

The pair kind (``--model pairwise``) is fitted once on the ``--scene`` task's data (experiment-lattice, a chain of
springs, experiment-gravity, a softened rotating disk, or experiment-lj, a Lennard-Jones cluster at the scene's
task settings, its cutoff 2.5: 8 bodies, the dataset of ``--seed``) by each of
``--fits``: ``library`` (the radial library, one solve), ``swim`` (sampled radial neurons, one solve) and ``adam``
(an MLP of (r, 1/r) by Adam, ``--adam-steps`` steps of batch 200); ``swim+table``, ``adam+table``: those models' V
as a table (``hnn.models.pair_table``; the fitted distances' closest pair to twice their farthest, slope error
1e-5): their paths near the true forces' cost. The same model, unchanged, then rolls out chains of each N of
``--sizes`` from ``--starts`` start states of the task's start law, by leapfrog at step ``--dt`` over
``--horizon``, float64. Beside it, the same leapfrog on the true forces (the task's: the chain's O(N), gravity's
every pair in blocks, ``hnn.orbits.nbody``, the cluster's pairs within the cutoff by a cell list), and the
reference: DOP853 at rtol 1e-10 (gravity and the cluster: yoshida4 on the true forces at a quarter of the step). A scene
may roll a fit out only to a smaller N by default (its ``largest``: gravity's sampled and Adam fits stop at 512,
their field calls at 4096 taking a minute or more); its rows past that say so, and ``--sizes`` runs every fit at
every size asked.

Per N and fit:
- **energy error per body**: max over t of |H(x(t)) - H(x(0))| / N along the model's path, H the true energy
  (mean over the starts); the same for the true-force leapfrog;
- **rollout error**: |x(T) - x_ref(T)| / |x_ref(T)| at the horizon (mean over the starts), both integrators;
- **seconds per step**: the median of ``REPEATS`` timed leapfrog rollouts of ``TIMED_STEPS`` steps of all
  starts at once, divided by the steps, for the model and for the true forces, measured in one process; where
  those would pass ``TIMING_BUDGET`` seconds (a step of seconds), the measured rollout's own, marked ``*``.

The fits run in the command's process; each N is then a cell of its own, measured one after another (the
default: every step timed alone), in ``--jobs`` processes, or as Ray tasks (``--backend ray``, on this machine or
the cluster at ``--ray-address``), one thread each. The rows are the same whichever way (the same starts, fits
and arithmetic); only the seconds per step of cells measured side by side share the machine, and the page's
first line says how they ran.

Prints a table, writes ``bodies.json`` and ``bodies.md`` under ``--out``, and with ``--update-docs`` the
``bodies`` section of docs/bodies.md. Numbers come from this command, never typed by hand.

``--paper`` (``hnn_analysis.scenes.bodies_paper``): the pair kind by Adam, the radial library and sampled radial
neurons on the 2-body and 3-body tasks at ``--seeds`` seeds, trained in one sweep of ``--jobs`` processes into
``--runs`` (default results/runs, which ``fit_tasks.py`` and the scene study reuse), each measured on the paper's
energy protocol, its one-thread training seconds and Sampling-HNNs' H error; writes ``bodies_paper.json`` and
``.md`` under ``--out`` and with ``--update-docs`` the ``bodies-paper`` section.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hnn.models.pair import RADIAL_WIDTH
from hnn.sweeps import flags
from hnn_analysis.commands import add_flags, portable_command, publish
from hnn_analysis.provenance import provenance
from hnn_analysis.scenes.bodies_study import FITS, QUICK_FITS, QUICK_SIZES, SCENES, study, table

DEFAULT_OUT = Path("results/bodies")


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    add_flags(p, quick=f"N = {', '.join(map(str, QUICK_SIZES))} and the least-squares fits only (no Adam)",
              out="folder for bodies.json and bodies.md", out_default=DEFAULT_OUT,
              update_docs="write the bodies section of docs/bodies.md")
    p.add_argument("--sizes", type=int, nargs="+",
                   help="body counts N (default: the scene's, " + ", ".join(f"{name} {scene['sizes']}" for name, scene
                                                                          in SCENES.items()) + f"; --quick {QUICK_SIZES})")
    p.add_argument("--fits", nargs="+", choices=FITS, help=f"how the pair kind is fitted, X+table: fit X's model "
                   f"tabulated (default {FITS}; --quick {QUICK_FITS})")
    p.add_argument("--scene", choices=SCENES, default="lattice",
                   help="the scene (its task): the chain of springs, gravity, or the Lennard-Jones cluster cut off "
                        "at 2.5 (default lattice)")
    p.add_argument("--seed", type=int, default=0, help="the training data's seed and the fits' (default 0)")
    p.add_argument("--starts", type=int, default=None, help="start states per N (default: the scene's, 4, 2, 2)")
    p.add_argument("--dt", type=float, default=None,
                   help="the leapfrog's step (default: the scene's, 0.05, 0.01, 0.01)")
    p.add_argument("--horizon", type=float, default=None,
                   help="the rollouts' length in time units (default: the scene's, 10, 0.5, 2)")
    p.add_argument("--adam-steps", dest="adam_steps", type=int, default=2000, help="Adam's steps (default 2000)")
    p.add_argument("--hidden-dim", dest="hidden_dim", type=int, default=RADIAL_WIDTH,
                   help=f"the MLP's width (adam) and the sampled neurons (swim) (default {RADIAL_WIDTH})")
    p.add_argument("--paper", action="store_true", help="the paper's 2-body and 3-body protocols instead (see above)")
    add_flags(p, seeds="--paper: seeds of every rung (default 5; --quick 1)", seeds_default=None,
              jobs="--paper: training processes (one thread each past one); else the sizes N measured at once, "
                   "one process of one thread each (default 1: seconds per step measured alone)")
    flags.add_backend_flags(p)
    p.add_argument("--runs", type=Path, default=None,
                   help="--paper: the runs folder (default results/runs, results-quick/runs with --quick)")
    args = p.parse_args(argv)
    flags.check_backend(p, args)
    if not args.paper and (args.device is not None or args.group != "auto"):
        p.error("--device and --group set how --paper's runs train; the sizes' rollouts run on the CPU, one "
                "process each: drop them, or add --paper")
    argv = list(sys.argv[1:] if argv is None else argv)
    if args.paper:
        return _paper(args, argv)
    scene = SCENES[args.scene]
    args.starts, args.dt, args.horizon = (scene[name] if value is None else value for name, value in
                                          (("starts", args.starts), ("dt", args.dt), ("horizon", args.horizon)))
    sizes = tuple(args.sizes or (QUICK_SIZES if args.quick else scene["sizes"]))
    fits = tuple(args.fits or (QUICK_FITS if args.quick else FITS))
    for value, name in ((args.starts, "--starts"), (args.dt, "--dt"), (args.horizon, "--horizon")):
        if not value > 0:
            raise SystemExit(f"{name} {value}: must be > 0")
    if min(sizes) < 2:
        raise SystemExit(f"--sizes {min(sizes)}: a chain needs at least 2 bodies")
    # the scene's default sizes roll each fit out as far as the scene says (its ``largest``); sizes asked, every fit
    largest = None if args.sizes else scene.get("largest")
    results = study(sizes, fits, args.seed, args.starts, args.dt, args.horizon, args.adam_steps, args.hidden_dim,
                    args.scene, largest, args.jobs, args.backend, args.ray_address)
    results["meta"] = {**provenance(), "command": portable_command(argv, "analysis/bodies.py")}
    text = table(results)
    stem = "bodies" if args.scene == "lattice" else f"bodies-{args.scene}"
    publish(args.out, stem, results, text, {scene["section"]: text} if args.update_docs else None)
    return results


def _paper(args, argv: list[str]) -> dict:
    """The paper's protocols (``bodies_paper``): train what the runs folder lacks, measure every seed, publish."""
    import hnn
    from hnn.sweeps import sweep
    from hnn_analysis import pages
    from hnn_analysis.scenes import bodies_paper

    if args.update_docs and args.quick:
        raise SystemExit("--update-docs writes the protocols' settings into docs/bodies.md; drop --quick")
    seeds = list(range(args.seeds or (1 if args.quick else 5)))
    root = hnn.tasks.repo_root() / ("results-quick" if args.quick else "results")
    tasks, runs = bodies_paper.train_and_measure(seeds, args.runs or root / "runs", args.quick, args.jobs, {
        "backend": args.backend, "ray_address": args.ray_address, "group": args.group, "device": args.device})
    results = {"meta": {**provenance(), "seeds": seeds, "quick": args.quick,
                        "command": portable_command(argv, "analysis/bodies.py")}, "tasks": tasks}
    text = bodies_paper.table(results)
    out = args.out if args.out != DEFAULT_OUT else root / "bodies"
    publish(out, "bodies_paper", results, text, {"bodies-paper": text} if args.update_docs else None,
            pages.Seeds(len(seeds), None if len(seeds) >= pages.MIN_SEEDS else "a --seeds run below 3"))
    sweep.exit_if_failed(runs)
    return results


if __name__ == "__main__":
    main()
