"""The cost of a Lennard-Jones field call against N, every pair against the pairs within a cutoff (a cell list).

    python analysis/benchmarks/cutoff_cost.py                         # N = 64, 512, 4096, r_c = 2.5
    python analysis/benchmarks/cutoff_cost.py --sizes 64 512 --rounds 5

At each N, one state of the cluster (``experiment-lj``'s start law at N bodies), float64, one torch thread, no
graph. Timed in interleaved rounds (each round calls every variant once, in turn, so a load that comes and goes
falls on all of them alike); the medians and their ratios:

- ``true, all``: the true forces over every pair (``dynamics(x)``), N(N-1)/2 pairs;
- ``true, cutoff``: the same with the cutoff (``dynamics(x, cutoff)``): the cell list, then the pairs it found;
- ``cells``: the cell list alone (``hnn.cells.pairs_within``);
- ``floor``: the cutoff's force arithmetic alone over the pairs already found (gather, distance, the force
  formula, the scatter): what the call would cost if finding the pairs were free;
- ``pair kind, all`` / ``pair kind, cutoff``: an untrained ``PairHNN`` (width ``--width``) of each layout.
  Past ``--pair_all_up_to`` bodies the all-pairs network call is skipped (at 4096 its 8.4 million pairs a state
  take the network and its autograd minutes a call): the true forces show the all-pairs growth there.

O(N) shows as a cutoff time that grows by about 8x from 64 to 512 and from 512 to 4096 (the bodies grow 8x), the
all-pairs time by about 64x. Prints a Markdown table and writes JSON to ``--out``.
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import torch

import hnn
from hnn.bodies import Bodies
from hnn.cells import pairs_within
from hnn.io import write_json
from hnn.models.pair import PairHNN
from hnn.threads import torch_threads
from hnn_analysis.provenance import cpu_snapshot, machine, others_load, provenance

VARIANTS = ("true, all", "true, cutoff", "cells", "floor", "pair kind, all", "pair kind, cutoff")


def _calls(count: int, cutoff: float, width: int, pair_all: bool) -> dict:
    """The variants' calls on one state of ``count`` bodies: name -> a function of no arguments."""
    data = hnn.load_task("lj")
    x = torch.tensor(data.initial_state(0, count))[None]
    q = data.layout(count).split(x)[0]
    i, j = pairs_within(q, cutoff)

    def floor():
        d = q[:, i] - q[:, j]
        r = torch.linalg.vector_norm(d, dim=-1)
        s6 = r ** -6
        push = (24 * (2 * s6 * s6 - s6) / r ** 2)[..., None] * d
        return torch.zeros_like(q).index_add(1, i, push).index_add(1, j, -push)

    torch.manual_seed(0)
    models = {name: PairHNN(bodies, hidden_dim=width).double() for name, bodies in
              (("all", Bodies(count, 2)), ("cutoff", Bodies(count, 2, pairs="cutoff", cutoff=cutoff)))}
    calls = {"true, all": lambda: data.dynamics(x), "true, cutoff": lambda: data.dynamics(x, cutoff),
             "cells": lambda: pairs_within(q, cutoff), "floor": floor,
             "pair kind, cutoff": lambda: models["cutoff"].time_derivative(x)}
    if pair_all:
        calls["pair kind, all"] = lambda: models["all"].time_derivative(x)
    return calls, len(i)


def measure(count: int, cutoff: float, width: int, rounds: int, pair_all: bool) -> dict:
    """Medians (ms) of each variant at ``count`` bodies over ``rounds`` interleaved rounds, and the pairs found."""
    calls, found = _calls(count, cutoff, width, pair_all)
    times = {name: [] for name in calls}
    start = cpu_snapshot()
    with torch_threads(1), hnn.modes.frozen_weights():
        for call in calls.values():             # one warm-up call each
            call()
        for k in range(rounds):
            names = list(calls)
            for name in names[k % len(names):] + names[:k % len(names)]:     # a rotating order
                t0 = time.perf_counter()
                calls[name]()
                times[name].append(time.perf_counter() - t0)
    return {"bodies": count, "pairs_within": found, "all_pairs": count * (count - 1) // 2,
            "ms": {name: 1e3 * statistics.median(t) for name, t in times.items()},
            "others": others_load(start, cpu_snapshot())}


def markdown(rows: list[dict]) -> str:
    out = ["| N | pairs within r_c | " + " | ".join(f"{v} (ms)" for v in VARIANTS)
           + " | true cutoff / all | cutoff / floor | others' load (cores) |",
           "| ---: | ---: | " + " | ".join("---:" for _ in VARIANTS) + " | ---: | ---: | ---: |"]
    for r in rows:
        cells = " | ".join(f"{r['ms'][v]:.3g}" if v in r["ms"] else "skipped" for v in VARIANTS)
        out.append(f"| {r['bodies']} | {r['pairs_within']} | {cells} | "
                   f"{r['ms']['true, cutoff'] / r['ms']['true, all']:.3g} | "
                   f"{r['ms']['true, cutoff'] / r['ms']['floor']:.3g} | {r['others']:.1f} |")
    if len(rows) > 1:
        out.append("")
        out.append("Growth from one N to the next (the bodies' ratio, then each variant's time ratio):")
        out.append("")
        for a, b in zip(rows, rows[1:]):
            growth = ", ".join(f"{v} {b['ms'][v] / a['ms'][v]:.3g}x" for v in VARIANTS if v in a["ms"] and v in b["ms"])
            out.append(f"- {a['bodies']} -> {b['bodies']} ({b['bodies'] / a['bodies']:.3g}x bodies): {growth}")
    return "\n".join(out)


def main(argv=None) -> dict:
    p = hnn.cli.Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", nargs="+", type=hnn.settings.int_at_least(2), default=[64, 512, 4096], help="bodies N")
    p.add_argument("--cutoff", type=hnn.settings.positive_float, default=2.5, help="r_c, in units of sigma")
    p.add_argument("--width", type=hnn.settings.int_at_least(1), default=64, help="the pair kind's hidden units")
    p.add_argument("--rounds", type=hnn.settings.int_at_least(3), default=9, help="interleaved rounds")
    p.add_argument("--pair_all_up_to", type=hnn.settings.int_at_least(2), default=512,
                   help="the largest N at which the all-pairs network is called")
    p.add_argument("--out", type=Path, default=Path("results/cutoff_cost.json"), help="JSON output")
    args = p.parse_args(argv)
    rows = [measure(n, args.cutoff, args.width, args.rounds, n <= args.pair_all_up_to) for n in args.sizes]
    meta = provenance()
    result = {"provenance": meta, "box": machine(meta), "cutoff": args.cutoff, "width": args.width,
              "rounds": args.rounds, "rows": rows, "table": markdown(rows)}
    print(f"{machine(meta)}, one torch thread, one state, float64, r_c = {args.cutoff:g}")
    print(result["table"])
    write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
