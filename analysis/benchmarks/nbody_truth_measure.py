"""The measuring and the table of ``analysis/benchmarks/nbody_truth.py`` (its docstring says what each column is):
the gravity task's true forces stepped by ours and by REBOUND, cost and accuracy against N."""
from __future__ import annotations

import statistics
import time

import numpy as np
import torch

import hnn
from hnn.interface import SplitField
from hnn.orbits import rebound_truth
from hnn_analysis import pages
from hnn_analysis.provenance import cpu_snapshot, machine, others_load

FULL_SIZES = (8, 64, 512, 4096)
QUICK_SIZES = (8, 64, 512)
# label -> (who, integrator, force evaluations a step; None: adaptive)
METHODS = {"ours leapfrog": ("ours", "leapfrog", 1), "ours yoshida4": ("ours", "yoshida4", 3),
           "REBOUND leapfrog": ("rebound", "leapfrog", 1), "REBOUND WHFast": ("rebound", "whfast", 1),
           "REBOUND IAS15": ("rebound", "ias15", None)}
REFERENCE = "REBOUND IAS15"
# one softened pair, counted once: dx, dy (2), r^2 + e^2 (3), its inverse square root (1), the cube (2), the pull's
# two components (2), added to body i and taken from body j (4), rounded up for the two bodies' loads
FLOPS_PER_PAIR = 16
# a timed run of a fixed-step method takes about this many pair interactions (N^2 a step), between MIN_TIMED_STEPS
# and TIMED_STEPS steps: a second or two at N = 4096, and enough steps at N = 8 that the timer's resolution does not
# count. At least 4: our leapfrog's call evaluates the forces once more for its first kick (k steps, k + 1
# evaluations), which one-step runs would count as a second evaluation a step
TIMED_PAIRS = 2 ** 22
MIN_TIMED_STEPS, TIMED_STEPS = 4, 20


def _timed_steps(count: int) -> int:
    return int(min(TIMED_STEPS, max(MIN_TIMED_STEPS, TIMED_PAIRS // count ** 2)))


def _matmul_rate(size: int = 512, repeats: int = 5) -> float:
    """Float64 operations per second of a ``size`` square matrix product on this thread (median of ``repeats``)."""
    a, b = torch.rand(size, size, dtype=torch.float64), torch.rand(size, size, dtype=torch.float64)
    a @ b                                                            # warm-up
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        a @ b
        times.append(time.perf_counter() - tic)
    return 2 * size ** 3 / statistics.median(times)


def _path(label: str, gravity, x0: torch.Tensor, t: np.ndarray, dt: float, softening: float,
          stats: dict | None = None) -> torch.Tensor:
    """``(1, len(t), 4N)`` states of ``label``'s integrator from ``x0``."""
    who, integrator, _ = METHODS[label]
    if who == "ours":
        truth = SplitField(lambda x: gravity.dynamics(x, softening), lambda p: p,
                           lambda q: gravity.potential_gradient(q, softening))
        with torch.no_grad():
            return hnn.rollout(truth, x0, t, method=integrator, dt=dt)
    return rebound_truth.rollout(x0, t, integrator, softening=softening, dt=None if integrator == "ias15" else dt,
                                 stats=stats)


def _seconds(label: str, gravity, x0: torch.Tensor, steps: int, dt: float, softening: float) -> float:
    """Seconds of ``steps`` fixed steps of ``label`` (ours: the whole call; REBOUND: its stepping)."""
    t = np.arange(steps + 1) * dt
    if METHODS[label][0] == "ours":
        tic = time.perf_counter()
        _path(label, gravity, x0, t, dt, softening)
        return time.perf_counter() - tic
    stats = {}
    _path(label, gravity, x0, t, dt, softening, stats)
    return stats["seconds"][0]


def _energy_per_body(path: torch.Tensor, gravity, softening: float, count: int) -> float:
    H = gravity.hamiltonian(path[0], softening)
    return float((H - H[0]).abs().max()) / count


def measure(sizes, seed: int, dt: float, horizon: float, repeats: int, softening: float) -> dict:
    """Every method at every N (see the module's docstring); prints a line per N as it ends."""
    gravity = hnn.load_task("gravity")
    t = np.linspace(0.0, horizon, int(round(horizon / dt)) + 1)
    start = cpu_snapshot()
    rate = _matmul_rate()
    rows = []
    for count in sizes:
        x0 = torch.tensor(gravity.random_config(np.random.RandomState(seed + 1000), count))[None]
        row = {"N": count, "pairs": count * (count - 1) // 2,
               "floor_ms": 1e3 * count * (count - 1) / 2 * FLOPS_PER_PAIR / rate, "methods": {}}
        ias15, paths = {}, {}
        for label in METHODS:
            tic = time.perf_counter()
            paths[label] = _path(label, gravity, x0, t, dt, softening, ias15 if label == REFERENCE else None)
            print(f"  N={count}: {label} to t = {horizon:g} in {time.perf_counter() - tic:.1f} s", flush=True)
        ref = paths[REFERENCE][0, -1]
        for label, path in paths.items():
            row["methods"][label] = {
                "energy_per_body": _energy_per_body(path, gravity, softening, count),
                "error_at_T": float(torch.linalg.vector_norm(path[0, -1] - ref) / torch.linalg.vector_norm(ref)),
                "evaluations_per_step": METHODS[label][2]}
        per_step = [s / k for s, k in zip(ias15["interval_seconds"][0], ias15["interval_steps"][0]) if k]
        row["methods"][REFERENCE].update(ms_per_step=1e3 * statistics.median(per_step), steps=ias15["steps"][0])
        fixed = [label for label in METHODS if label != REFERENCE]
        steps = _timed_steps(count)
        for label in fixed:                                       # warm-up: first-call setup
            _seconds(label, gravity, x0, 1, dt, softening)
        samples = {label: [] for label in fixed}
        for _ in range(repeats):
            for label in fixed:
                samples[label].append(_seconds(label, gravity, x0, steps, dt, softening) / steps)
        for label in fixed:
            row["methods"][label].update(ms_per_step=1e3 * statistics.median(samples[label]), steps=len(t) - 1,
                                         timed_steps=steps)
        rows.append(row)
        print(f"N={count}: floor {row['floor_ms']:.3g} ms | " + " | ".join(
            f"{label} {m['ms_per_step']:.3g} ms E/N {m['energy_per_body']:.2e}" for label, m in row["methods"].items()),
            flush=True)
    return {"rows": rows, "matmul_gflops": rate / 1e9, "others_load": others_load(start, cpu_snapshot()),
            "settings": {"sizes": list(sizes), "seed": seed, "dt": dt, "horizon": horizon, "repeats": repeats,
                         "softening": softening, "starts": 1, "flops_per_pair": FLOPS_PER_PAIR, "threads": 1,
                         "rebound": rebound_truth.version()}}


def _ratio(a: float, b: float) -> str:
    return f"{a / b:,.0f}x" if a / b >= 100 else f"{a / b:.1f}x"


def table(results: dict) -> str:
    """The page's section: cost per step against N beside the floor, then the energy and path errors."""
    meta, settings, rows = results["meta"], results["settings"], results["rows"]
    labels = list(METHODS)
    lines = [pages.generated_by(meta, f"{machine(meta)}, torch {meta.get('torch', '?')}, REBOUND "
                                      f"{settings['rebound']}, one thread; other processes kept "
                                      f"{results['others_load']:.1f} cores busy") + ".", "",
             f"One start of the gravity task's disk per N (seed {settings['seed']}, softening "
             f"{settings['softening']:g}), to t = {settings['horizon']:g} at dt = {settings['dt']:g} (IAS15: its own "
             f"steps), float64. Floor: one force evaluation, N(N - 1)/2 pairs of {settings['flops_per_pair']} "
             f"operations at a float64 matrix product's {results['matmul_gflops']:.1f} GFLOP/s on one thread.", "",
             "**ms per step** (median; x floor: a leapfrog step's one force evaluation against the floor)", "",
             "| N | pairs | floor | " + " | ".join(labels) + " | IAS15 steps to T |",
             "|---|---:|---:|" + "---:|" * len(labels) + "---:|"]
    for row in rows:
        m = row["methods"]
        cells = []
        for label in labels:
            cell = f"{m[label]['ms_per_step']:.3g}"
            if METHODS[label][2] == 1 and METHODS[label][1] == "leapfrog":
                cell += f" ({_ratio(m[label]['ms_per_step'], row['floor_ms'])})"
            cells.append(cell)
        lines.append(f"| {row['N']} | {row['pairs']} | {row['floor_ms']:.3g} | " + " | ".join(cells)
                     + f" | {m[REFERENCE]['steps']} |")
    lines += ["", f"**energy error per body** (max over t <= {settings['horizon']:g}) **/ error at T against IAS15**",
              "", "| N | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for row in rows:
        m = row["methods"]
        lines.append(f"| {row['N']} | " + " | ".join(
            f"{m[label]['energy_per_body']:.2e}" + ("" if label == REFERENCE else f" / {m[label]['error_at_T']:.2e}")
            for label in labels) + " |")
    last = rows[-1]
    m = last["methods"]
    lines += ["", f"- At N = {last['N']}: our leapfrog's step takes "
                  f"{_ratio(m['ours leapfrog']['ms_per_step'], m['REBOUND leapfrog']['ms_per_step'])} REBOUND's "
                  f"leapfrog's time, which is {_ratio(m['REBOUND leapfrog']['ms_per_step'], last['floor_ms'])} the "
                  "floor; IAS15's step "
                  f"{_ratio(m[REFERENCE]['ms_per_step'], m['REBOUND leapfrog']['ms_per_step'])} REBOUND's leapfrog step, "
                  f"{m[REFERENCE]['steps']} steps to t = {settings['horizon']:g} against "
                  f"{m['REBOUND leapfrog']['steps']}.",
              f"- WHFast at N = {last['N']}: energy error per body "
              f"{_ratio(m['REBOUND WHFast']['energy_per_body'], m['REBOUND leapfrog']['energy_per_body'])} REBOUND's "
              f"leapfrog's, error at T {_ratio(m['REBOUND WHFast']['error_at_T'], m['REBOUND leapfrog']['error_at_T'])} "
              "its, at the same step."]
    return "\n".join(lines) + "\n"


