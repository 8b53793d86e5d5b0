"""Each least-squares fit beside its arithmetic floor: the fits to time (``FITS``), the calls each makes,
their floor and the section of docs/speed.md (``analysis/fits/fit_floor.py`` is the command).
A benchmark, not a test: it prints a table and writes JSON, and passes or fails nothing. Each fit (``FITS``: the
Sampling-HNNs protocols, ``hnn_analysis.fits.sampling_protocols``, at their settings on 2 threads; the paper's
tasks' library, sampled and SINDy fits on one thread, as ``train.py`` runs them) runs ``--repeats`` times
through ``hnn.fits.solve`` (the fit's own ``seconds``: the sampling, the factors, the solve and the
thresholding). One more run under a dispatch recorder lists every LAPACK and BLAS call the fit makes (QR,
SVD, triangular solve, matrix product, dtpqrt's folds: shapes and flops; a fit of minutes, ``Fit.once``, is
timed by that run alone, its floor's calls once after it; QR of m x n: 2mn^2 - 2n^3/3, SVD of
n x n: 22n^3, product m x k x n: 2mkn, a fold of an n x n triangle 2n^3/3); the floor is each of those calls timed alone on fresh operands of its shape at
the same thread count, plus the features' build (rows x columns x input width flops at the matrix-multiply
rate). ``ratio`` = the fit's median / the floor; ``gemm floor``: every flop at the float64 matrix-multiply
rate measured here (no QR runs at that rate: the Householder panels are matrix-vector work). pysindy's
SINDy is timed whole; its floor is one QR of its library's columns beside dx/dt (the least squares it
must solve at least once). Times on a shared box move with its load: the fit and its floor alternate.
"""

from __future__ import annotations

import resource
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from scipy.linalg import lapack
from torch.utils._python_dispatch import TorchDispatchMode

import hnn
from hnn.specs import ModelSpec
from hnn.threads import torch_threads
from hnn_analysis import pages
from hnn_analysis.fits import sampling_protocols as protocols
from hnn_analysis.provenance import machine


SECTION = "fit-floor"


@dataclass(frozen=True)
class Fit:
    """One fit to time: ``data`` names its states (a protocol or a task), ``kind`` and ``fit`` as
    ``hnn.fit_least_squares``; ``spec``: ``ModelSpec`` fields; ``solve``: ``hnn.fits.solve`` keywords."""
    label: str
    data: str
    kind: str
    fit: str
    threads: int
    spec: dict = field(default_factory=dict)
    solve: dict = field(default_factory=dict)
    slow: bool = False          # minutes a fit: skipped by --quick
    once: bool = False          # timed once, under the recorder that lists its calls (a fit of minutes: no repeats)


FITS = [
    Fit("single pendulum, SWIM width 1000 (Sampling-HNNs, rcond 1e-13)", "single", "hnn", "swim", 2,
        {"hidden_dim": 1000}, {"rcond": protocols.RCOND}),
    Fit("single pendulum, SWIM width 1000, ridge by cross-validation", "single", "hnn", "swim", 2,
        {"hidden_dim": 1000}, {"rcond": "auto"}),
    Fit("pend task, HNN SWIM width 1000", "pend", "hnn", "swim", 1, {"hidden_dim": 1000}),
    Fit("pend task, HNN library", "pend", "hnn", "library", 1, {"library_degree": 3, "library_frequencies": 1}),
    Fit("3-body task, HNN library (cubic, 790 terms)", "3body", "hnn", "library", 1,
        {"library_degree": 2, "library_frequencies": 1}),
    Fit("3-body task, baseline library (dx/dt's terms)", "3body", "baseline", "library", 1,
        {"library_degree": 2, "library_frequencies": 1}),
    Fit("3-body task, SINDy (pysindy)", "3body", "baseline", "sindy", 1, {"library_degree": 2, "library_frequencies": 1}),
    # their 121 s on 64 threads (docs/fits.md, fits-sampling); last, so that the peak memory column is its own
    Fit("double pendulum, SWIM width 10000 (Sampling-HNNs, rcond 1e-13)", "double", "hnn", "swim", 2,
        {"hidden_dim": 10000}, {"rcond": protocols.RCOND}, slow=True, once=True),
]


def dataset(name: str, data_dir: Path | None) -> dict:
    """``x``, ``dxdt`` and, for a protocol, its ``anchor``: a Sampling-HNNs protocol's seed 0, or a task's
    dataset of seed 0 (cached in the task's folder as ``train.py`` caches it, or in ``data_dir``)."""
    if name in protocols.PROTOCOLS:
        protocol = protocols.PROTOCOLS[name]
        data = protocols.dataset(protocol, 0)
        return {"x": data["x"], "dxdt": data["dxdt"], "anchor": protocols.anchor(protocol)}
    task = hnn.load_task(name)
    data = task.get_dataset(seed=0, **({"save_dir": data_dir} if data_dir is not None and name != "pend" else {}))
    return {"x": np.asarray(data["x"], dtype=np.float64), "dxdt": np.asarray(data["dxdt"], dtype=np.float64)}


class _Calls(TorchDispatchMode):
    """Every QR, SVD, triangular solve and matrix product below it: ``(op, shape)``; and, while it is entered,
    every triangle folded by LAPACK's dtpqrt (``StreamingQR.add_triangular``, scipy: no torch op sees it)."""

    def __init__(self):
        super().__init__()
        self.calls: list[tuple[str, tuple]] = []

    def __enter__(self):
        fold = self._fold = hnn.fits.lstsq.StreamingQR.add_triangular
        calls = self.calls

        def add_triangular(solver, T, Y):
            calls.append(("tpqrt", (solver.columns, solver.columns + solver.rhs)))
            return fold(solver, T, Y)
        hnn.fits.lstsq.StreamingQR.add_triangular = add_triangular
        return super().__enter__()

    def __exit__(self, *exc):
        hnn.fits.lstsq.StreamingQR.add_triangular = self._fold
        return super().__exit__(*exc)

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        if func is torch.ops.aten.linalg_qr.default:
            self.calls.append(("qr", tuple(args[0].shape)))
        elif func is torch.ops.aten._linalg_svd.default:
            self.calls.append(("svd", tuple(args[0].shape)))
        elif func is torch.ops.aten.linalg_solve_triangular.default:
            self.calls.append(("trsm", tuple(args[0].shape) + (args[1].shape[-1],)))
        elif func is torch.ops.aten.mm.default:
            self.calls.append(("mm", tuple(args[0].shape) + (args[1].shape[-1],)))
        return func(*args, **(kwargs or {}))


def flops(op: str, shape: tuple) -> float:
    """The flops of one call: QR (m, n) 2mn^2 - 2n^3/3 (m >= n), SVD (n, n) 22n^3, triangular solve (n, n, k)
    n^2 k, product (m, k, n) 2mkn, a triangle (k, n) folded into a triangle (dtpqrt) 2/3 k^3 + 2 k^2 (n - k)."""
    if op == "tpqrt":
        k, n = shape
        return 2 * k ** 3 / 3 + 2 * k * k * (n - k)
    if op == "qr":
        m, n = shape
        n, m = min(m, n), max(m, n)
        return 2 * m * n * n - 2 * n ** 3 / 3
    if op == "svd":
        return 22 * min(shape) ** 3
    if op == "trsm":
        return shape[0] ** 2 * shape[2]
    m, k, n = shape
    return 2 * m * k * n


def _alone(op: str, shape: tuple, repeats: int) -> float:
    """The median seconds of one such call on fresh float64 operands (``repeats`` times; once past 5 s)."""
    gen = torch.Generator().manual_seed(sum(shape))
    if op == "qr":
        A = torch.randn(*shape, generator=gen, dtype=torch.float64)
        run = lambda: torch.linalg.qr(A, mode="r")      # noqa: E731
    elif op == "svd":
        A = torch.randn(*shape, generator=gen, dtype=torch.float64)
        run = lambda: torch.linalg.svd(A)               # noqa: E731
    elif op == "trsm":
        R = torch.randn(shape[0], shape[1], generator=gen, dtype=torch.float64).triu() + 4 * torch.eye(shape[0],
                                                                                                     dtype=torch.float64)
        B = torch.randn(shape[0], shape[2], generator=gen, dtype=torch.float64)
        run = lambda: torch.linalg.solve_triangular(R, B, upper=True)    # noqa: E731
    elif op == "tpqrt":
        k, n = shape
        top = np.triu(torch.randn(n, n, generator=gen, dtype=torch.float64).numpy()) + 4 * np.eye(n)
        block = np.triu(torch.randn(k, n, generator=gen, dtype=torch.float64).numpy())
        # fresh Fortran copies a call: dtpqrt overwrites both, as add_triangular lets it
        run = lambda: lapack.dtpqrt(k, min(64, n), np.asfortranarray(top), np.asfortranarray(block),  # noqa: E731
                                    overwrite_a=1, overwrite_b=1)
    else:
        A = torch.randn(shape[0], shape[1], generator=gen, dtype=torch.float64)
        B = torch.randn(shape[1], shape[2], generator=gen, dtype=torch.float64)
        run = lambda: A @ B                             # noqa: E731
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        run()
        times.append(time.perf_counter() - tic)
        if times[-1] > 5:
            break
    return statistics.median(times)


def gemm_rate(repeats: int = 5, n: int = 2000) -> float:
    """Float64 flops per second of an n x n product at the current thread count (median of ``repeats``)."""
    return flops("mm", (n, n, n)) / _alone("mm", (n, n, n), repeats)


def _model(case: Fit, dim: int):
    return hnn.fits.build(ModelSpec(kind=case.kind, input_dim=dim, fit=case.fit, **case.spec))


def _features_flops(model, rows: int) -> float:
    """rows x columns x input width of each part's features (the basis its design is factored through)."""
    total = 0.0
    for part in model.parts():
        columns = part.columns
        if part.factored is not None:
            basis, V, _ = part.factored()
            columns = V.shape[0]
        total += rows * columns * part.features.in_dim
    return total


def measure(case: Fit, data: dict, repeats: int, rates: dict) -> dict:
    """The fit's seconds (median of ``repeats``), its calls and its floor (see the module's docstring), at
    ``case.threads`` torch threads (the caller's count back after)."""
    with torch_threads(case.threads):
        return _measure(case, data, repeats, rates)


def _measure(case: Fit, data: dict, repeats: int, rates: dict) -> dict:
    if case.threads not in rates:
        rates[case.threads] = gemm_rate()
    rate = rates[case.threads]
    x, dxdt = data["x"], data["dxdt"]
    kwargs = {"fit": case.fit, "seed": 0, "progress": False, "anchor": data.get("anchor"), **case.solve}

    def run(recorder=None) -> float:
        model = _model(case, x.shape[1])
        if recorder is None:
            return hnn.fits.solve(model, x, dxdt, **kwargs)["seconds"]
        # the training loss solve() reports after its seconds: not the fit's, so not its floor's calls
        loss, hnn.fits.fitting.derivative_mse = hnn.fits.fitting.derivative_mse, lambda *a, **k: [float("nan")]
        try:
            with recorder:
                return hnn.fits.solve(model, x, dxdt, **kwargs)["seconds"]
        finally:
            hnn.fits.fitting.derivative_mse = loss

    if case.fit == "sindy":
        library = _model(case, x.shape[1]).features.width
        calls = [("qr", (len(x), library + x.shape[1]))]
        feature_flops = 0.0
    else:
        recorder = _Calls()
        recorded = run(recorder)
        calls, feature_flops = recorder.calls, _features_flops(_model(case, x.shape[1]), len(x))
    alone = {key: None for key in calls}
    # a fit of minutes (``once``) is timed by its recorded run: the recorder's Python per torch call is
    # milliseconds of its minutes
    seconds, floors = ([recorded], []) if case.once else ([], [])
    for _ in range(1 if case.once else repeats):    # the fit and its floor alternate: the load hits both alike
        if not case.once:
            seconds.append(run())
        for key in alone:
            alone[key] = _alone(*key, repeats=1)
        floors.append(sum(alone[key] for key in calls) + feature_flops / rate)
    total = sum(flops(*key) for key in calls) + feature_flops
    big = sorted({key for key in calls if flops(*key) >= 0.05 * total}, key=lambda k: -flops(*k))
    return {"label": case.label, "threads": case.threads, "rows": len(x), "seconds": statistics.median(seconds),
            "each": seconds, "floor": statistics.median(floors), "gflop": total / 1e9, "gemm_floor": total / rate,
            "gemm_gflops": rate / 1e9, "ratio": statistics.median(seconds) / statistics.median(floors),
            "calls": len(calls), "main": [f"{op} {'x'.join(map(str, shape))} ({calls.count((op, shape))}x)"
                                          for op, shape in big],
            "peak_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20}


def _load_note(results: dict, cores: int) -> str:
    """The box's load during the run: the cores other processes kept busy (``others``; the load average, which
    counts this command's own threads and the job before it, where a saved run lacks it)."""
    others = results.get("others")
    if others is None:
        busy = results["load"][0] > 0.5 * cores
        return (f". Measured on a loaded box (load average {results['load'][0]:.1f} on {cores} cores before, "
                f"{results['load'][1]:.1f} after): the seconds are inflated, fit and floor alike; rerun the command on "
                "a quiet box") if busy else ""
    if others > 0.5:
        return (f". Measured on a loaded box (other processes kept {others:.1f} of {cores} cores busy): the seconds "
                "are inflated, fit and floor alike; rerun the command on a quiet box")
    return f"; other processes kept {others:.1f} cores busy"


def section(results: dict) -> str:
    """The fit-floor section: one row a fit."""
    meta = results["meta"]
    lines = [pages.generated_by(meta, f"{machine(meta)}, torch {meta['torch']}; median of {results['repeats']} "
                                      "fits, the floor's calls timed between them")
             + _load_note(results, meta["cores"]) + ".",
             "", "| fit | threads | rows | fits timed | seconds | floor (s) | ratio | GFLOP | at the gemm rate (s) | "
                 "the floor's largest calls | peak GiB so far |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: |"]
    for row in results["rows"]:
        lines.append(f"| {row['label']} | {row['threads']} | {row['rows']} | {len(row['each'])} | {row['seconds']:.3g} "
                     f"| {row['floor']:.3g} | {row['ratio']:.2f} | {row['gflop']:.3g} | {row['gemm_floor']:.3g} | "
                     f"{'; '.join(row['main'])} | {row['peak_gib']:.1f} |")
    rates = ", ".join(f"{t} thread(s) {g:.3g}" for t, g in sorted(results["gemm_gflops"].items()))
    lines += ["", f"Floor: every QR, SVD, triangular solve, product and dtpqrt fold the fit makes, each timed alone on fresh "
              f"operands of its shape, plus its features' build (rows x columns x input width at the matrix-multiply "
              f"rate); ratio = seconds / floor. The float64 matrix-multiply rate here, GFLOP/s: {rates}. SINDy's "
              "floor is one QR of its library's columns beside dx/dt. A row of one fit timed is a fit of minutes: "
              "that fit ran under the recorder that lists its calls, the floor's calls timed once after it. Peak GiB "
              "so far: the process's peak resident memory once the row ran (rows run in this order)."]
    return "\n".join(lines) + "\n"
