"""The arithmetic floor of a training step: the matrix products it performs, each timed alone.

    found = floor.products(step)                     # every product one call of step() performs
    result = floor.compare(step, found, rounds=200)  # step and floor alternately: medians, ratio

``products`` runs the step once under a dispatch mode, which sees every aten call below autograd,
so the backward's and the double backward's products are counted as the step really performs
them, not as a count of the model's layers predicts. ``compare`` times each product alone on
fresh operands of its shape, in whichever of its eight layouts (each operand and the result row-
or column-major) the BLAS runs fastest at the current thread count: the floor is what the
products cost at best, not in the layout the step happens to use (a 750x200 @ 200x2 product is
5x slower in one layout than in another). It then alternates blocks of steps and of floors and
reports the medians and their ratio, so load from other processes hits both alike; it also reports
the ratio of the fastest rounds.
"""
from __future__ import annotations

import math
import statistics
import time
from typing import Callable

import numpy as np
import torch
from torch.utils._python_dispatch import TorchDispatchMode

# operand positions of the (M, K) and (K, N) matrices in each product op the floor knows; the
# batched ones multiply (B, M, K) by (B, K, N) and are recorded as (B, M, K, N)
_PRODUCT_OPS = {torch.ops.aten.mm.default: (0, 1), torch.ops.aten.addmm.default: (1, 2),
                torch.ops.aten.bmm.default: (0, 1), torch.ops.aten.baddbmm.default: (1, 2)}
# products the floor would miss if a step used them: refuse rather than understate the floor
_UNHANDLED = {torch.ops.aten.mv.default, torch.ops.aten.addmv.default, torch.ops.aten.dot.default}


class _ProductRecorder(TorchDispatchMode):
    def __init__(self):
        super().__init__()
        self.shapes: list[tuple[int, int, int]] = []
        self.unhandled: list[str] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        if func in _PRODUCT_OPS:
            i, j = _PRODUCT_OPS[func]
            self.shapes.append(tuple(args[i].shape) + (args[j].shape[-1],))
        elif func in _UNHANDLED:
            self.unhandled.append(str(func))
        return func(*args, **(kwargs or {}))


def products(step: Callable[[], object]) -> list[tuple[int, ...]]:
    """``(M, K, N)`` of every matrix product one call of ``step`` performs, in call order
    (``(B, M, K, N)`` for a batched one)."""
    recorder = _ProductRecorder()
    with recorder:
        step()
    if recorder.unhandled:
        raise NotImplementedError(f"the step calls {sorted(set(recorder.unhandled))}, which the floor does not "
                                  "time; add them to analysis/benchmarks/floor.py's _PRODUCT_OPS")
    return recorder.shapes


def _median_seconds(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        fn()
        times.append(time.perf_counter() - tic)
    return statistics.median(times)


def _layouts(*shape: int, dtype: torch.dtype = torch.float32, with_numpy: bool = False):
    """The eight ways to compute one (M, K) @ (K, N) product (``shape`` ``(M, K, N)``), or one batched
    (B, M, K) @ (B, K, N) product (``(B, M, K, N)``): ``(label, fn)`` on fresh operands; with
    ``with_numpy`` also numpy's ``dot`` on the same operands of a 2-D one (an evaluation path may
    use either)."""
    *batch, m, k, n = shape
    gen = torch.Generator().manual_seed(m * 1_000_003 + k * 1009 + n + 7 * sum(batch))
    product = torch.bmm if batch else torch.mm
    for swapped in (False, True):               # C, or C^T = B^T A^T into a (N, M) result
        p, q = (n, m) if swapped else (m, n)
        for left_t in (False, True):
            for right_t in (False, True):
                left = torch.randn((*batch, k, p) if left_t else (*batch, p, k), generator=gen, dtype=dtype)
                right = torch.randn((*batch, q, k) if right_t else (*batch, k, q), generator=gen, dtype=dtype)
                left, right = (left.mT if left_t else left), (right.mT if right_t else right)
                out = torch.empty(*batch, p, q, dtype=dtype)
                label = f"{'C^T' if swapped else 'C'} {'col' if left_t else 'row'}/{'col' if right_t else 'row'}"
                yield label, lambda left=left, right=right, out=out: product(left, right, out=out)
                if with_numpy and not batch:
                    a, b, c = left.numpy(), right.numpy(), out.numpy()
                    yield "numpy " + label, lambda a=a, b=b, c=c: np.dot(a, b, out=c)


def _fastest_layout(*shape: int, repeats: int = 15, dtype: torch.dtype = torch.float32, with_numpy: bool = False):
    """``(label, fn, seconds)`` of the layout of this product (``_layouts``' ``shape``) that runs
    fastest here and now."""
    best = None
    for label, fn in _layouts(*shape, dtype=dtype, with_numpy=with_numpy):
        fn()
        fn()
        seconds = _median_seconds(fn, repeats)
        if best is None or seconds < best[2]:
            best = (label, fn, seconds)
    return best


def _floor(shapes, dtype: torch.dtype = torch.float32, with_numpy: bool = False):
    """``(fn, {shape: (label, fn, seconds)})``: ``fn`` runs every product of ``shapes`` once, each in
    its fastest layout."""
    fastest = {shape: _fastest_layout(*shape, dtype=dtype, with_numpy=with_numpy) for shape in sorted(set(shapes))}
    runners = [fastest[shape][1] for shape in shapes]

    def floor():
        for run in runners:
            run()
    return floor, fastest


def floor_ms(shapes: list[tuple[int, ...]], rounds: int = 50) -> float:
    """The median milliseconds of the products ``shapes`` run back to back, each in its fastest layout
    (float32, the current thread count): the floor alone, for a step timed elsewhere."""
    floor, _ = _floor(shapes)
    floor()
    return _median_seconds(floor, rounds) * 1e3


def compare(step: Callable[[], object], shapes: list[tuple[int, int, int]], rounds: int = 200,
            warmup: int = 30, block: int = 10, dtype: torch.dtype = torch.float32, with_numpy: bool = False) -> dict:
    """Step and floor timed ``rounds`` times each (after ``warmup`` steps), at the current thread
    count, alternating in blocks of ``block`` of each; the floor runs each product of ``shapes`` in
    its fastest layout (in ``dtype``; with ``with_numpy`` numpy's ``dot`` competes too). Blocks, not single calls, because the step runs back to back in training,
    with the last step's arrays in cache: a floor run between two steps evicts them (measured: the
    spring step 25% slower at 2 threads when alternated one by one)."""
    for _ in range(warmup):
        step()
    floor, fastest = _floor(shapes, dtype, with_numpy)

    t_step, t_floor = [], []
    while len(t_step) < rounds:
        for fn, times in ((step, t_step), (floor, t_floor)):
            fn()                                      # refills the cache with this side's arrays
            for _ in range(min(block, rounds - len(times))):
                tic = time.perf_counter()
                fn()
                times.append(time.perf_counter() - tic)
    step_s, floor_s = statistics.median(t_step), statistics.median(t_floor)
    # the fastest round of each is what the machine gives when nothing else runs: on a shared
    # machine their ratio is the steadier one
    return {"threads": torch.get_num_threads(), "rounds": rounds, "step_ms": step_s * 1e3, "floor_ms": floor_s * 1e3,
            "ratio": step_s / floor_s, "best_step_ms": min(t_step) * 1e3, "best_floor_ms": min(t_floor) * 1e3,
            "best_ratio": min(t_step) / min(t_floor), "products": len(shapes), "gflop": sum(2 * math.prod(shape) for shape in shapes) / 1e9,
            "per_shape": [{"shape": list(shape), "count": shapes.count(shape), "layout": fastest[shape][0],
                           "ms": fastest[shape][2] * 1e3} for shape in sorted(set(shapes), key=shapes.index)]}


def describe_products(shapes: list[tuple[int, int, int]], large: float = 0.05) -> str:
    """E.g. ``'6 x 750x200x200 + 5 small'``: products of at least ``large`` of the step's FLOPs by
    shape, the rest counted."""
    flops = [m * k * n for m, k, n in shapes]
    total = sum(flops)
    big = [s for s, f in zip(shapes, flops) if f >= large * total]
    counts: dict[tuple[int, int, int], int] = {}
    for m, k, n in big:     # one shape up to transposition: (750, 200, 200) and (200, 750, 200) alike
        key = tuple(sorted((m, k, n), reverse=True))
        counts[key] = counts.get(key, 0) + 1
    parts = [f"{c} x {'x'.join(map(str, key))}" for key, c in counts.items()]
    small = len(shapes) - len(big)
    return " + ".join(parts + ([f"{small} small"] if small else []))
