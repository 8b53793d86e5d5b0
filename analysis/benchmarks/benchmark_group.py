"""Grouped training against separate runs: the ``group`` job of ``analysis/benchmarks/benchmark.py``.

    python analysis/benchmarks/benchmark.py --jobs group            # widths 16, 32, 64, 200; G = 1, 4, 16, 64
    python analysis/benchmarks/benchmark.py --jobs group --quick    # widths 16, 64, 200; G = 1, 4, 16

For each hidden width and group size G: G spring HNNs (seeds 0..G-1 for the init and the
minibatches, the seed-0 dataset, 750 x 2 full batch, as the scene study's grid) trained for the
same steps by ``hnn.trainers.closed_form.train_closed_form`` as one program, against the same G models trained one
after another by ``hnn.train`` (the separate runs' time is that of ``min(G, 4)`` of them scaled
to G: separate runs are independent, each costs the same). Both in this process, at the
benchmark's thread count, alternated for ``repeats`` rounds; the table gives model-steps per
second (G x steps / seconds) of each and their ratio, the speedup of grouping, and the grouped
step's ratio to its floor: the batched matrix products one grouped step performs (captured by
``floor.products`` during one step), each timed alone in its fastest layout in this process
(``floor.floor_ms``).
"""
from __future__ import annotations

import copy
import statistics
import time

import torch

import hnn
from hnn.trainers.closed_form import train_closed_form
from hnn_analysis.benchmarks import floor

WIDTHS, SIZES = (16, 32, 64, 200), (1, 4, 16, 64)
QUICK_WIDTHS, QUICK_SIZES = (16, 64, 200), (1, 4, 16)
_SEPARATE_SAMPLE = 4      # separate runs timed per cell; the rest scaled from them


def _models(width: int, size: int) -> list:
    out = []
    for seed in range(size):
        torch.manual_seed(seed)
        out.append(hnn.build_model(2, width))
    return out


def _grouped_seconds(models, data, steps: int) -> float:
    models = copy.deepcopy(models)
    pairs, tests = [(data["x"], data["dxdt"])] * len(models), [(data["test_x"], data["test_dxdt"])] * len(models)
    tic = time.perf_counter()
    train_closed_form(models, pairs, tests, seeds=list(range(len(models))), total_steps=steps)
    return time.perf_counter() - tic


def _group_products(models, data) -> list[tuple[int, ...]]:
    """The matrix products of one grouped training step (no test data: a step's products only)."""
    models = copy.deepcopy(models)
    pairs = [(data["x"], data["dxdt"])] * len(models)
    return floor.products(lambda: train_closed_form(models, pairs, seeds=list(range(len(models))), total_steps=0))


def _separate_seconds(models, data, steps: int) -> float:
    sample = copy.deepcopy(models[:_SEPARATE_SAMPLE])
    tic = time.perf_counter()
    for seed, model in enumerate(sample):
        hnn.train(model, data["x"], data["dxdt"], data["test_x"], data["test_dxdt"], total_steps=steps, seed=seed,
                  progress=False, threads=None)
    return (time.perf_counter() - tic) * len(models) / len(sample)


def job_group(quick: bool, steps: int | None = None, repeats: int = 1) -> dict:
    """``{"rows": [{width, models, steps, grouped_steps_per_s, separate_steps_per_s, speedup, floor_ms,
    floor_ratio}], "table": str}``."""
    widths, sizes = (QUICK_WIDTHS, QUICK_SIZES) if quick else (WIDTHS, SIZES)
    steps = steps if steps is not None else (100 if quick else 300)
    data = hnn.load_task("spring").get_dataset(seed=0)
    warm = _models(widths[0], 2)           # first calls pay one-time setup: not part of either side
    _grouped_seconds(warm, data, 5), _separate_seconds(warm, data, 5)
    rows = []
    for width in widths:
        for size in sizes:
            models = _models(width, size)
            together, apart = [], []
            for _ in range(repeats):
                together.append(_grouped_seconds(models, data, steps))
                apart.append(_separate_seconds(models, data, steps))
            work = size * (steps + 1)
            row = {"width": width, "models": size, "steps": steps + 1,
                   "grouped_steps_per_s": work / statistics.median(together),
                   "separate_steps_per_s": work / statistics.median(apart),
                   "floor_ms": floor.floor_ms(_group_products(models, data))}
            row["speedup"] = row["grouped_steps_per_s"] / row["separate_steps_per_s"]
            row["floor_ratio"] = statistics.median(together) / (steps + 1) * 1e3 / row["floor_ms"]
            rows.append(row)
            print(f"group: width {width:3d}, G {size:2d}: grouped {row['grouped_steps_per_s']:8.0f} model-steps/s, "
                  f"separate {row['separate_steps_per_s']:8.0f}, {row['speedup']:.2f}x; grouped step "
                  f"{row['floor_ratio']:.1f}x its products' floor ({row['floor_ms']:.3f} ms)", flush=True)
    return {"rows": rows, "table": markdown(rows), "threads": torch.get_num_threads()}


def markdown(rows: list[dict]) -> str:
    lines = [f"Grouped training (`hnn.trainers.closed_form.train_closed_form`) of G spring HNNs (750 x 2 full batch, "
             f"{rows[0]['steps'] if rows else 0} steps, {torch.get_num_threads()} thread(s)) against G separate "
             "`hnn.train` runs, in model-steps per second; the floor: the batched matrix products of one grouped "
             "step, each alone in its fastest layout, timed in the same process:", "",
             "| width | G | grouped (model-steps/s) | separate (model-steps/s) | grouped / separate | "
             "grouped products' floor (ms) | grouped step / floor |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lines.append(f"| {r['width']} | {r['models']} | {r['grouped_steps_per_s']:.0f} | "
                     f"{r['separate_steps_per_s']:.0f} | {r['speedup']:.2f}x | {r['floor_ms']:.3f} | "
                     f"{r['floor_ratio']:.1f}x |")
    return "\n".join(lines)
