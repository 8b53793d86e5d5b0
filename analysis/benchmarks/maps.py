"""The learned maps on the SympNets protocols, beside our HNN + RK4, + midpoint and the separable HNN +
leapfrog at equal training budget: test-horizon error and rollout seconds per step, medians over seeds,
and one step of each against its arithmetic floor (``map_protocols`` says what each protocol is).

    python analysis/benchmarks/maps.py --quick                      # a smoke run: few steps, 2 seeds
    python analysis/benchmarks/maps.py --protocols pendulum --seeds 5 --update-docs
    python analysis/benchmarks/maps.py --protocols three_body --seeds 5 --update-docs

Each protocol writes ``<out>/maps-<protocol>.json`` and ``.md`` and, with ``--update-docs``, its section
of docs/maps.md (``maps-<protocol>``). The issue's goal (#72): a map's rollout step at least 4x cheaper
than HNN + RK4's at the same width, at a test-horizon error within 2x of it; each map's row says both.
Every number is measured in this process, one thread.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


import hnn
from hnn.threads import torch_threads
from hnn_analysis import commands, pages
from hnn_analysis.benchmarks import map_protocols as mp
from hnn_analysis.benchmarks.map_report import goals, section, summarize
from hnn_analysis.provenance import provenance

SEEDS = 5


def _parser() -> argparse.ArgumentParser:
    p = hnn.cli.Parser(prog="maps.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--protocols", nargs="+", default=list(mp.PROTOCOLS), choices=list(mp.PROTOCOLS),
                   help="the SympNets protocols to run (default: both)")
    p.add_argument("--repeats", type=hnn.settings.int_at_least(1), default=None,
                   help="timed rollouts per model (default 11; --quick 3)")
    p.add_argument("--floor-rounds", type=hnn.settings.int_at_least(1), default=None,
                   help="step/floor rounds of the step table (default 200; --quick 20)")
    commands.add_flags(p, quick="smoke run: each protocol's quick training steps, 2 seeds, 250 3-body orbits",
                       out="output folder (default results/ or results-quick/)", out_default=None,
                       seeds=f"seeds of every model (default {SEEDS}; --quick 2)", seeds_default=None,
                       update_docs="write each protocol's section of docs/maps.md (full settings only)")
    return p


@torch_threads(1)       # one torch thread, the caller's count back after (tests call main in-process)
def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _parser()
    args = parser.parse_args(argv)
    if args.update_docs and args.quick:
        parser.error("--update-docs writes full-settings results into docs/maps.md; drop --quick")
    args.seeds = args.seeds or (2 if args.quick else SEEDS)
    repeats = args.repeats or (3 if args.quick else 11)
    rounds = args.floor_rounds or (20 if args.quick else 200)
    out = args.out or hnn.tasks.repo_root() / ("results-quick" if args.quick else "results")
    results = {}
    for name in args.protocols:
        protocol = mp.PROTOCOLS[name]
        result = run(protocol, args.seeds, args.quick, repeats, rounds, out)
        result["meta"]["command"] = "python analysis/benchmarks/maps.py " + " ".join(
            "DIR" if Path(a).is_absolute() else a for a in argv)
        text = section(result)
        seeds = pages.Seeds(args.seeds, None if args.seeds >= pages.MIN_SEEDS else "a --seeds run below the study's")
        commands.publish(out, f"maps-{name}", result, text, {f"maps-{name}": text} if args.update_docs else {}, seeds)
        results[name] = result
    return results


def run(protocol: mp.Protocol, seeds: int, quick: bool, repeats: int, rounds: int, out: Path) -> dict:
    """Every model of ``protocol`` at each seed, its medians over seeds, and seed 0's step against its floor."""
    tic = time.perf_counter()
    arrays = mp.data(protocol, out / "data", quick)
    rows, seed0, trained = [], {}, {}
    for seed in range(seeds):
        for label in mp.labels(protocol):
            row, model = mp.train_and_measure(protocol, label, seed, arrays, quick, repeats, trained)
            rows.append(row)
            print(f"  {protocol.name} seed {seed} {label}: horizon error {row['horizon_error']:.3g}, "
                  f"{row['seconds_per_step'] * 1e6:.1f} us/step, trained in {row['train_seconds']:.1f} s", flush=True)
            if seed == 0:
                seed0[label] = model
    x0 = arrays["test"][:, 0]
    floors = mp.step_and_floor(protocol, seed0, x0, rounds)
    summary = summarize(rows)
    return {"meta": {**provenance(), "quick": quick, "seeds": list(range(seeds)), "repeats": repeats,
                     "protocol": {"name": protocol.name, "h": protocol.h, "width": protocol.width,
                                  "steps": protocol.quick_steps if quick else protocol.steps, "batch": protocol.batch,
                                  "learn_rate": protocol.learn_rate, "train_pairs": len(arrays["pairs"]),
                                  "test_starts": len(arrays["test"]), "test_steps": arrays["test"].shape[1] - 1,
                                  "maps": {k: {"class": c.__name__, **kw} for k, (c, kw) in protocol.maps.items()}},
                     "seconds": time.perf_counter() - tic},
            "rows": rows, "summary": summary, "goals": goals(summary, protocol), "floors": floors}


if __name__ == "__main__":
    main()
