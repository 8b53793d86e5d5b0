"""Time and size the pixel task: rendering its dataset, one training step, and peak memory.

    python analysis/benchmarks/benchmark_pixels.py                  # render the full dataset, 300 steps per model
    python analysis/benchmarks/benchmark_pixels.py --steps 10000    # the full training of both models
    python analysis/benchmarks/benchmark_pixels.py --update-docs  # write the table into docs/speed.md

Renders the 200 x 103 frames afresh into a temporary folder (gymnasium, ``--workers``
processes), builds the training arrays, then trains the HNN and the baseline for ``--steps``
steps each at the paper's settings (batch 200, Adam lr 1e-3, weight decay 1e-5) and reports
the median seconds per step and the extrapolated time of the full 10001 steps. Peak memory is
this process's maximum resident set size (rendering workers excluded; they hold one trial
each). Prints a Markdown table and writes JSON to --out. Timings on a busy machine are noisy.
"""
from __future__ import annotations

import argparse
import os
import sys
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.models import PixelHNN
from hnn.objectives import pixel_loss
from hnn.io import write_json
from hnn_analysis import commands, pages
from hnn_analysis.provenance import machine, provenance

FULL_STEPS = 10001


def _peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024    # Linux reports KiB


def time_training(data: dict, baseline: bool, steps: int, seed: int = 0) -> dict:
    """Median seconds per optimizer step of the paper's loop (minibatch draw, loss, backward, Adam)."""
    torch.manual_seed(seed)
    model = PixelHNN(data["pixels"].shape[1], 2, 200, baseline=baseline)
    x, x_next = torch.as_tensor(data["pixels"]), torch.as_tensor(data["next_pixels"])
    optim = torch.optim.Adam(model.parameters(), lr=1e-3, weight_decay=1e-5, fused=True)
    gen = torch.Generator().manual_seed(seed)
    torch.set_flush_denormal(True)      # as hnn.train does
    times, losses = [], []
    for _ in range(steps):
        tic = time.perf_counter()
        ix = torch.randperm(len(x), generator=gen)[:200]
        loss = pixel_loss(model, x[ix], x_next[ix]).mean()
        loss.backward()
        optim.step()
        optim.zero_grad(set_to_none=True)
        times.append(time.perf_counter() - tic)
        losses.append(loss.item())
    warm = times[min(20, len(times) // 5):]
    per_step = statistics.median(warm)
    return {"steps": steps, "seconds": sum(times), "median_step_ms": per_step * 1e3,
            "full_training_s_estimate": per_step * FULL_STEPS, "final_loss": losses[-1]}


def main(argv=None) -> dict:
    p = hnn.cli.Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=300, help="training steps timed per model")
    p.add_argument("--workers", type=int, default=None, help="rendering processes (default: the cores)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=None, help="JSON path (default results/benchmark_pixels.json)")
    p.add_argument("--update-docs", dest="update_docs", action="store_true",
                        help="write the generated section of docs/speed.md")
    args = p.parse_args(argv)
    system = hnn.load_task("pixels")
    out = args.out or hnn.tasks.repo_root() / "results" / "benchmark_pixels.json"
    data_workers = args.workers or os.cpu_count() or 1
    with tempfile.TemporaryDirectory() as tmp:
        tic = time.perf_counter()
        data = system.get_dataset(seed=args.seed, save_dir=tmp, workers=args.workers)
        render_s = time.perf_counter() - tic
        cache_mib = sum(f.stat().st_size for f in Path(tmp).glob("*.npz")) / 2 ** 20
    arrays_mib = sum(v.nbytes for v in data.values() if isinstance(v, np.ndarray)) / 2 ** 20
    frames = data["frames"].shape[0] * data["frames"].shape[1]
    peak_after_data = _peak_mib()
    train = {label: time_training(data, label == "baseline", args.steps, args.seed) for label in ("hnn", "baseline")}
    result = {**provenance(), "frames": frames, "render_seconds": render_s,
              "render_ms_per_frame": render_s / frames * 1e3, "cache_mib": cache_mib, "arrays_mib": arrays_mib,
              "peak_rss_mib_after_data": peak_after_data, "peak_rss_mib": _peak_mib(), "train": train}
    rows = [f"| render {frames} frames (+ cache) | {render_s:.1f} s | {result['render_ms_per_frame']:.2f} ms/frame |",
            *(f"| train {label}: {t['steps']} steps | {t['seconds']:.1f} s | {t['median_step_ms']:.1f} ms/step, "
              f"full {FULL_STEPS} steps ~ {t['full_training_s_estimate']:.0f} s |" for label, t in train.items()),
            f"| dataset in memory | {arrays_mib:.0f} MiB | cache file {cache_mib:.1f} MiB |",
            f"| peak resident memory | {result['peak_rss_mib']:.0f} MiB | after the data: {peak_after_data:.0f} MiB |"]
    command = commands.portable_command(list(argv) if argv is not None else sys.argv[1:], "analysis/benchmarks/benchmark_pixels.py")
    text = (pages.generated_by({**result, "command": command}, f"{machine(result)}, {result['threads']} torch threads, "
                         f"torch {torch.__version__}, rendering in {data_workers} processes") + ":\n\n"
            "| stage | time / size | note |\n| --- | --- | --- |\n"
            + "\n".join(rows))
    print(text)
    write_json(out, result)
    print(f"wrote {out}")
    if args.update_docs:
        pages.update_section("benchmark-pixels", text)
        print("updated docs/speed.md")
    return result


if __name__ == "__main__":
    main()
