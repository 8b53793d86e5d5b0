"""The Sampling-HNNs protocols on this box: our least-squares fit of a sampled HNN beside their published
per-seed numbers (Rahma, Datar & Dietrich 2024), and our Adam HNN on the same data.

    python analysis/fits/sampling_hnns.py                       # single pendulum 1000, double 5000 and 10000, 5 seeds
    python analysis/fits/sampling_hnns.py --quick               # single pendulum, width 1000, 1 seed (seconds)
    python analysis/fits/sampling_hnns.py --update-docs         # docs/fits.md, section fits-sampling

Each (system, width) runs in a fresh process (its peak resident memory is the width's), every seed and
variant one after another on ``--threads`` threads: uniform pairs (``uswim``: dx/dt alone, ``--fit swim``),
pairs by the true H at the training points (``swim``: their headline SWIM) and ``elm``, as many as a
width's fits allow (``sampling_protocols.default_variants``) unless ``--variants`` says otherwise. Then ``--adam-seeds`` seeds of the paper's HNN trained by Adam for ``--adam-steps`` steps on the
double pendulum's data. Writes ``<out>/sampling_hnns.json`` and ``.md``; the protocol and where ours
differs: ``analysis/fits/sampling_protocols.py`` and docs/fits.md.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import multiprocessing
import statistics
import sys
from pathlib import Path

import hnn
from hnn_analysis import commands, pages
from hnn_analysis.fits import sampling_protocols as sp
from hnn_analysis.provenance import cpu_snapshot, others_load, provenance


def _width(name: str, width: int, variants: list[str], seeds: list[int], threads: int) -> list[dict]:
    """Every variant and seed of one (system, width), in this (fresh) process."""
    rows = []
    for variant in variants:
        runs = []
        for seed in seeds:
            start = cpu_snapshot()
            runs.append({**sp.fit_one(name, width, variant, seed, threads), "others": others_load(start, cpu_snapshot()),
                         "seed": seed})
            print(f"  {name} {width} {variant} seed {seed}: error {runs[-1]['error']:.3g} in "
                  f"{runs[-1]['seconds']:.3g} s", flush=True)
        rows.append({"protocol": name, "width": width, "variant": variant, "per_seed": runs,
                     "error": sp.summary([r["error"] for r in runs]),
                     "seconds": statistics.median(r["seconds"] for r in runs),
                     "peak_gib": max(r["peak_gib"] for r in runs),
                     "others": statistics.median(r["others"] for r in runs)})
    return rows


def _adam(seeds: list[int], threads: int, steps: int) -> list[dict]:
    runs = []
    for seed in seeds:
        runs.append({**sp.adam_one("double", seed, threads, steps), "seed": seed})
        print(f"  double Adam seed {seed}: error {runs[-1]['error']:.3g} in {runs[-1]['seconds']:.3g} s", flush=True)
    return [{"protocol": "double", "steps": steps, "per_seed": runs, "error": sp.summary([r["error"] for r in runs]),
             "seconds": statistics.median(r["seconds"] for r in runs)}] if runs else []


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    p = hnn.cli.Parser(prog="sampling_hnns.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--protocols", nargs="+", choices=list(sp.PROTOCOLS), default=list(sp.PROTOCOLS),
                   help="the systems (default: both)")
    p.add_argument("--widths", nargs="+", type=hnn.settings.int_at_least(1), default=None,
                   help="hidden widths (default: each system's published widths: single 1000, double 5000 10000)")
    p.add_argument("--variants", nargs="+", choices=list(sp.VARIANTS), default=None,
                   help="; ".join(f"{k}: {v}" for k, v in sp.VARIANTS.items())
                   + " (default: all three at width 1000, uswim and swim at 5000, uswim alone at 10000: a fit there "
                     "takes minutes on 2 cores)")
    p.add_argument("--threads", type=hnn.settings.int_at_least(1), default=2, help="torch threads of every fit")
    p.add_argument("--adam-seeds", type=hnn.settings.int_at_least(0), default=5, help="seeds of the Adam HNN (0: none)")
    p.add_argument("--adam-steps", type=hnn.settings.int_at_least(1), default=3000,
                   help="Adam steps a seed (batch 2048; theirs: 180000 on 64 threads)")
    commands.add_flags(p, quick="single pendulum, width 1000, one seed, no Adam: a smoke run of seconds",
                       out="output folder (default results/fits)", out_default=Path("results/fits"),
                       seeds="seeds of every fit (default 5; theirs: 10)", seeds_default=5,
                       update_docs="write docs/fits.md's section fits-sampling (full settings only)")
    args = p.parse_args(argv)
    if args.update_docs and args.quick:
        p.error("--update-docs writes the full protocols into docs/fits.md; drop --quick")
    if args.quick:
        args.protocols, args.widths, args.seeds, args.adam_seeds = ["single"], [1000], 1, 0
    seeds = list(range(args.seeds))
    plan = [(name, width) for name in args.protocols
            for width in (args.widths or sp.PROTOCOLS[name].widths)]
    results = {"meta": {**provenance(), "threads": args.threads, "seeds": seeds, "quick": args.quick,
                        "command": commands.portable_command(argv, "analysis/fits/sampling_hnns.py")}, "rows": []}
    context = multiprocessing.get_context("spawn")     # a fresh process per width: its peak memory is that width's
    for name, width in plan:
        with concurrent.futures.ProcessPoolExecutor(1, mp_context=context) as pool:
            variants = args.variants or sp.default_variants(width)
            results["rows"] += pool.submit(_width, name, width, variants, seeds, args.threads).result()
    if args.adam_seeds and "double" in args.protocols:
        results["adam"] = _adam(list(range(args.adam_seeds)), args.threads, args.adam_steps)
    others = [r["others"] for row in results["rows"] for r in row["per_seed"]]
    results["others_median"] = statistics.median(others) if others else 0.0
    text = sp.markdown(results)
    commands.publish(args.out, "sampling_hnns", results, text, {"fits-sampling": text} if args.update_docs else {},
                     pages.Seeds(len(seeds), None if len(seeds) >= pages.MIN_SEEDS else "a --seeds run below 3"))
    return results


if __name__ == "__main__":
    main()
