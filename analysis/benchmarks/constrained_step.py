"""A constrained kind's training step against the paper HNN's on the same chain snippets.

    python analysis/benchmarks/constrained_step.py                   # N = 5, width 256, batch 200
    python analysis/benchmarks/constrained_step.py --bobs 2 --rounds 10

One training step of each kind as ``experiment-chain/train.py`` trains it on CHNN's protocol: the
snippet loss (4 RK4 steps of the model from each snippet's first state, MAE) of one batch of 200
snippets, its backward and an AdamW step. The HNN reads the chain's [q, qdot]; the constrained
kinds read the same snippets as the bobs' Cartesian [x, xdot]. The kinds alternate step by step
within each round, so a busy machine slows them alike; the table gives each kind's median step
and its ratio to the HNN's median, and the CPU seconds other processes ran meanwhile. One torch
thread. Writes ``constrained_step.json`` (and prints the table) under ``--out``.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import torch
from tqdm.auto import tqdm

import hnn
from hnn.io import write_json
from hnn.threads import torch_threads
from hnn_analysis.provenance import cpu_snapshot, machine, others_load, provenance

KINDS = ("hnn", "constrained", "constrained_lagrangian")


def _stepper(kind: str, bobs: int, width: int, batch: int, save_dir: str):
    """``step()``: one training step of a fresh ``kind`` model on the first ``batch`` snippets."""
    config = hnn.tasks.task_config("chain", {"model": kind, "bobs": bobs, "hidden_dim": width, "save_dir": save_dir})
    prep = hnn.prepare(config)      # the run's model (seed 0), its snippets and its loss
    model = prep.canonical_model
    loss = prep.options.loss_of(model)
    snippets = torch.as_tensor(prep.dataset[prep.objective.arrays[0]][:batch], dtype=torch.float32)
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-5, weight_decay=config.weight_decay)

    def step() -> None:
        optimizer.zero_grad()
        loss(snippets, snippets).mean().backward()
        optimizer.step()
    return step


def measure(bobs: int, width: int, batch: int, rounds: int, steps: int, save_dir: str) -> dict:
    """``{kind: {"median_ms", "ratio", "samples_ms"}}`` and the machine's load, steps alternated by kind."""
    steppers = {kind: _stepper(kind, bobs, width, batch, save_dir) for kind in KINDS}
    for step in steppers.values():        # warm-up: first calls build caches
        step()
        step()
    samples = {kind: [] for kind in KINDS}
    start = cpu_snapshot()
    for _ in tqdm(range(rounds), desc="rounds", leave=False):
        for _ in range(steps):
            for kind, step in steppers.items():
                tic = time.perf_counter()
                step()
                samples[kind].append(1e3 * (time.perf_counter() - tic))
    load = others_load(start, cpu_snapshot())
    base = statistics.median(samples["hnn"])
    return {"kinds": {kind: {"median_ms": statistics.median(ms), "ratio": statistics.median(ms) / base,
                             "samples_ms": ms} for kind, ms in samples.items()},
            "others_load": load}


def table(result: dict) -> str:
    """The printed table: each kind's median step and its ratio to the HNN's."""
    meta = result["meta"]
    lines = [f"training step, N = {meta['bobs']}, width {meta['width']}, batch {meta['batch']} snippets, 4 RK4 steps, "
             f"one thread ({machine(meta)}; other processes kept {result['others_load']:.1f} cores busy)",
             "| kind | median step (ms) | x HNN |", "| --- | --- | --- |"]
    lines += [f"| {kind} | {row['median_ms']:.1f} | {row['ratio']:.2f} |" for kind, row in result["kinds"].items()]
    return "\n".join(lines)


@torch_threads(1)       # one torch thread, the caller's count back after (tests call main in-process)
def main(argv=None) -> dict:
    p = hnn.cli.Parser(prog="constrained_step.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bobs", type=hnn.settings.int_at_least(1), default=5, help="bobs N of the chain")
    p.add_argument("--width", type=hnn.settings.int_at_least(1), default=256, help="hidden units")
    p.add_argument("--batch", type=hnn.settings.int_at_least(1), default=200, help="snippets a step")
    p.add_argument("--rounds", type=hnn.settings.int_at_least(1), default=5, help="rounds of alternated steps")
    p.add_argument("--steps", type=hnn.settings.int_at_least(1), default=5, help="steps of each kind per round")
    p.add_argument("--out", type=Path, default=hnn.tasks.repo_root() / "results" / "speed",
                   help="folder of constrained_step.json (and of the chain's cached dataset)")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    args.out.mkdir(parents=True, exist_ok=True)
    result = measure(args.bobs, args.width, args.batch, args.rounds, args.steps, str(args.out))
    result["meta"] = {**provenance(), "bobs": args.bobs, "width": args.width, "batch": args.batch,
                      "rounds": args.rounds, "steps": args.steps}
    print(table(result))
    write_json(args.out / "constrained_step.json", result)
    return result


if __name__ == "__main__":
    main()
