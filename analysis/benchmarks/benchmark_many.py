"""Many models at once, on every device present: model-steps per second of K paper-sized spring HNNs.

    python analysis/benchmarks/benchmark_many.py                       # K = 1, 16, 128 on the CPU; 1 .. 1024 on a GPU
    python analysis/benchmarks/benchmark_many.py --sizes 1 16 --steps 5 # smaller
    python analysis/benchmarks/benchmark_many.py --update-docs          # docs/speed.md (CPU), docs/gpu.md (GPU)

K HNNs of the paper's spring shape (2-200-200-1 tanh, the seed-0 dataset's 750 rows as one full
batch, Adam at lr 1e-3 and weight decay 1e-4), each step timed four ways in one process:

- ``anchor``: the plain batched step, written here in a few lines: weights stacked along a model
  axis, the forward by ``baddbmm``/``bmm``, the symplectic gradient by ``torch.autograd.grad`` with
  ``create_graph``, one fused Adam over the stacks. The yardstick a group must reach.
- ``group``: ``hnn.trainers.closed_form.train_closed_form`` (the tanh MLP's closed-form input gradient and its
  hand-written backward, batched over the model axis): no double backward.
- ``stacked``: ``hnn.trainers.vmap.train_vmap`` on the same models (``torch.func.vmap`` over the model
  axis, ``torch.func.grad`` for the input gradient): the path every other kind takes.
- ``lone``: ``hnn.train`` on one model after another (K = 1 and 16 only; its rate does not depend on K).

Each cell is the median over ``--repeats`` of (wall time of ``--steps`` steps) after one warm-up
call; model-steps per second = K x steps / seconds. The table says the device, torch version and
thread count.
"""
from __future__ import annotations

import sys
from pathlib import Path

import torch

import hnn

from hnn_analysis import commands
from hnn_analysis.benchmarks.many_models import WIDTH, measure
from hnn_analysis.provenance import machine, provenance
from hnn_analysis.pages import generated_by

ROWS_NOTE = "750 x 2 full batch"
CPU_SIZES, GPU_SIZES = (1, 16, 128), (1, 16, 128, 1024)


def table(rows: list[dict], meta: dict) -> str:
    device = rows[0]["device"] if rows else "?"
    where = meta.get("gpu") or machine(meta)
    lines = [generated_by(meta, f"{device}, {where}, torch {meta['torch']}, {meta['threads']} thread(s)")
             + f": K spring HNNs 2-{WIDTH}-{WIDTH}-1 tanh, {ROWS_NOTE}, "
             f"Adam; model-steps per second, median of {meta['repeats']} x {rows[0]['steps'] if rows else 0} steps. "
             "anchor: the plain batched `bmm` step with autograd's double backward; group: `hnn.trainers.closed_form.train_closed_form` "
             "(closed form); stacked: `hnn.trainers.vmap.train_vmap` (vmap, every kind's path); lone: one model after "
             "another.", "",
             "| K | anchor | group | stacked | lone | group / anchor | group / lone |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lone = f"{r['lone']:.0f}" if "lone" in r else "-"
        per_lone = f"{r['group'] / r['lone']:.2f}x" if "lone" in r else "-"
        lines.append(f"| {r['models']} | {r['anchor']:.0f} | {r['group']:.0f} | {r['stacked']:.0f} | {lone} | "
                     f"{r['group'] / r['anchor']:.2f}x | {per_lone} |")
    return "\n".join(lines)


def main(argv=None) -> dict:
    parser = hnn.cli.Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=None,
                        help=f"group sizes K (default: {CPU_SIZES} on the CPU, {GPU_SIZES} on a GPU)")
    parser.add_argument("--steps", type=int, default=10, help="steps a timed call (default 10)")
    parser.add_argument("--repeats", type=int, default=3, help="timed calls a cell (default 3)")
    parser.add_argument("--devices", nargs="+", default=None, help="torch devices (default: cpu and cuda if present)")
    commands.add_flags(parser, out="folder for many_models.json and .md", out_default=Path("results-bench"),
                       update_docs="write the CPU table into docs/speed.md and a GPU's into docs/gpu.md")
    args = parser.parse_args(argv)
    devices = args.devices or ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    meta = {**provenance(), "repeats": args.repeats,
            "command": commands.portable_command(sys.argv[1:] if argv is None else list(argv),
                                                 "analysis/benchmarks/benchmark_many.py")}
    results, texts, sections = {"meta": meta, "rows": {}}, [], {}
    for name in devices:
        device = torch.device(name)
        sizes = args.sizes or (CPU_SIZES if device.type == "cpu" else GPU_SIZES)
        rows = measure(device, sizes, args.steps, args.repeats)
        here = {**meta, "gpu": torch.cuda.get_device_name(device) if device.type == "cuda" else None}
        results["rows"][name] = rows
        texts.append(table(rows, here))
        if args.update_docs:
            sections["many-models" if device.type == "cpu" else "many-models-gpu"] = texts[-1]
    commands.publish(args.out, "many_models", results, "\n\n".join(texts) + "\n", sections)
    return results


if __name__ == "__main__":
    main()
