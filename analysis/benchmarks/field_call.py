"""A learned field's call on a rollout's few states against its own matrix products, in one process.

    python analysis/benchmarks/field_call.py                      # HNN and baseline, width 200, float64
    python analysis/benchmarks/field_call.py --kinds hnn --batches 1 15 --rounds 400

Each model kind's ``time_derivative`` on 1, 15 and 64 states, as ``hnn.rollout`` makes the call (no
graph, inside ``hnn.modes.frozen_weights``, one torch thread), alternated in blocks with the products
its arithmetic needs (``benchmark_rollouts.field_products``), each product timed alone in its fastest
layout, torch's or numpy's (``analysis/benchmarks/floor.py``). Prints a Markdown table (medians, their
ratio, the ratio of the fastest rounds, the load other processes put on the box meanwhile) and writes
JSON to ``--out``. The issue's targets: within 3x of the products on one state, within 2x on 15.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch

import hnn
from hnn.io import write_json
from hnn.threads import torch_threads
from hnn_analysis.benchmarks import floor
from hnn_analysis.benchmarks.benchmark_rollouts import DIM, DTYPES, KINDS, build, field_products
from hnn_analysis.provenance import cpu_snapshot, machine, others_load, provenance


def measure(kind: str, width: int, dtype: torch.dtype, batch: int, rounds: int) -> dict:
    """One field call of ``kind`` on ``batch`` states against its products' floor (``floor.compare``)."""
    model = build(kind, width).to(dtype)
    x = torch.randn(batch, DIM, generator=torch.Generator().manual_seed(batch)).to(dtype)

    def call():
        with torch.no_grad():
            return model.time_derivative(x)
    start = cpu_snapshot()
    with torch_threads(1), hnn.modes.frozen_weights():     # as inside hnn.rollout: the field runs as its kernel
        r = floor.compare(call, field_products(kind, batch, width), rounds=rounds, warmup=max(10, rounds // 10),
                          block=max(5, rounds // 20), dtype=dtype, with_numpy=True)
    return {"kind": kind, "width": width, "dtype": str(dtype).removeprefix("torch."), "batch": batch,
            "call_us": r["step_ms"] * 1e3, "floor_us": r["floor_ms"] * 1e3, "ratio": r["ratio"],
            "best_ratio": r["best_ratio"], "others": others_load(start, cpu_snapshot())}


def markdown(rows: list[dict]) -> str:
    out = ["| field call (no graph) | width | dtype | states | call (us) | its products alone (us) | call / products "
           "| fastest rounds | others' load (cores) |", "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        out.append(f"| {r['kind']} | {r['width']} | {r['dtype']} | {r['batch']} | {r['call_us']:.1f} | "
                   f"{r['floor_us']:.1f} | {r['ratio']:.2f}x | {r['best_ratio']:.2f}x | {r['others']:.1f} |")
    return "\n".join(out)


def main(argv=None) -> dict:
    p = hnn.cli.Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--kinds", nargs="+", default=["hnn", "baseline"], choices=KINDS, help="model kinds")
    p.add_argument("--width", type=hnn.settings.int_at_least(1), default=200, help="hidden units")
    p.add_argument("--dtype", default="float64", choices=sorted(DTYPES), help="the states' and weights' dtype")
    p.add_argument("--batches", nargs="+", type=hnn.settings.int_at_least(1), default=[1, 15, 64], help="states a call")
    p.add_argument("--rounds", type=hnn.settings.int_at_least(10), default=300, help="timed calls (and floors) each")
    p.add_argument("--out", type=Path, default=Path("results/field_call.json"), help="JSON output")
    args = p.parse_args(argv)
    rows = [measure(kind, args.width, DTYPES[args.dtype], batch, args.rounds)
            for kind in args.kinds for batch in args.batches]
    meta = provenance()
    result = {"provenance": meta, "box": machine(meta), "rows": rows, "table": markdown(rows)}
    print(f"{machine(meta)}, one torch thread")
    print(result["table"])
    write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
