"""Rollouts of learned models against their arithmetic floor: the ``rollout`` job of ``analysis/benchmarks/benchmark.py``.

Three tables, each measured in one process at one torch thread (a rollout of a few states runs on
one, ``hnn.rollout`` sees to that):

- field: one ``time_derivative`` call of each model kind (HNN, separable, dissipative, baseline;
  widths 200 and 32; 4 dims) on 1, 15 and 64 states in float32 and float64, as a rollout makes it
  (no graph, inside ``hnn.modes.frozen_weights``),
  against the matrix products its arithmetic needs, each timed alone in its fastest layout
  (``analysis/benchmarks/floor.py``; numpy's ``dot`` competes with torch's), alternated in blocks;
- step: one step of each fixed-step method (8 float64 states, width 200: leapfrog and yoshida4 on
  the separable HNN, rk4 and the midpoint rule on the HNN) against the field calls it makes
  (``stats['nfev']`` per step, the separable halves counted as halves), each timed alone;
- adaptive: ``hnn.rollout(method='dop853')`` and ``'dopri5'`` against ``torchdiffeq.odeint(method='dopri5')``
  on the same learned field and scipy's DOP853 (``method='solve_ivp'``), each at the same
  tolerances and at equal error (ours at the loosest tolerance of a ladder, rtol * 2^k, that is
  at least as accurate as theirs): 64 starts, t in [0, 30], float64, errors against DOP853 at
  rtol = atol = 1e-12. torchdiffeq is a benchmark extra
  (``pip install hnn[bench]``); without it that column is left out with a notice.
"""
from __future__ import annotations

import functools
import statistics
import time

import numpy as np
import torch

import hnn
from hnn.threads import torch_threads
from hnn_analysis.benchmarks import floor

KINDS = ("hnn", "separable", "dissipative", "baseline")
WIDTHS = (200, 32)
BATCHES = (1, 15, 64)
DTYPES = {"float32": torch.float32, "float64": torch.float64}
DIM = 4
STEP_BATCH, STEP_WIDTH, STEP_DT, STEP_SPAN = 8, 200, 0.01, 1.0
STEP_METHODS = (("leapfrog", "separable"), ("yoshida4", "separable"), ("rk4", "hnn"), ("midpoint", "hnn"))
ADAPTIVE_STARTS, ADAPTIVE_SPAN, ADAPTIVE_POINTS = 64, 30.0, 100


def build(kind: str, width: int, dim: int = DIM) -> torch.nn.Module:
    """An untrained model of ``kind`` (its arithmetic is what is timed), seeded."""
    torch.manual_seed(0)
    makers = {"hnn": lambda: hnn.build_model(dim, width), "baseline": lambda: hnn.build_model(dim, width, baseline=True),
              "separable": lambda: hnn.SeparableHNN(dim, width), "dissipative": lambda: hnn.DissipativeHNN(dim, width)}
    return makers[kind]().eval()


def field_products(kind: str, batch: int, width: int, dim: int = DIM) -> list[tuple[int, int, int]]:
    """``(M, K, N)`` of the products one field call needs: the forward pass and, for the input
    gradient, the backward through the hidden layer and the input layer (one per scalar read)."""
    if kind == "separable":
        return 2 * field_products("hnn", batch, width, dim // 2)[:3] + 2 * [(batch, width, dim // 2)]
    forward = [(batch, dim, width), (batch, width, width)]
    if kind == "baseline":
        return forward + [(batch, width, dim)]
    scalars = 2 if kind == "dissipative" else 1
    return forward + [(batch, width, scalars * width), (batch, scalars * width, dim)]


def field_table(rounds: int) -> list[dict]:
    """Each model kind's field call against its products' floor (``floor.compare``, one thread)."""
    rows = []
    for kind in KINDS:
        for width in WIDTHS:
            for dname, dtype in DTYPES.items():
                model = build(kind, width).to(dtype)
                for batch in BATCHES:
                    x = torch.randn(batch, DIM, generator=torch.Generator().manual_seed(batch)).to(dtype)

                    def call(model=model, x=x):
                        with torch.no_grad():
                            return model.time_derivative(x)
                    shapes = field_products(kind, batch, width)
                    with hnn.modes.frozen_weights():    # as inside hnn.rollout: the field runs as its kernel
                        r = floor.compare(call, shapes, rounds=rounds, warmup=max(10, rounds // 10),
                                          block=max(5, rounds // 20), dtype=dtype, with_numpy=True)
                    rows.append({"kind": kind, "width": width, "dtype": dname, "batch": batch,
                                 "call_us": r["step_ms"] * 1e3, "floor_us": r["floor_ms"] * 1e3, "ratio": r["ratio"],
                                 "best_ratio": r["best_ratio"]})
    return rows


def step_table(repeats: int) -> list[dict]:
    """Each fixed-step method's step against the field calls it makes (8 float64 states): a whole
    rollout against the same number of calls in a loop, alternated, medians of ``repeats`` each."""
    rows = []
    t = np.linspace(0.0, STEP_SPAN, 11)
    steps = round(STEP_SPAN / STEP_DT)
    for method, kind in STEP_METHODS:
        model = build(kind, STEP_WIDTH).double()
        x0 = 0.5 * torch.randn(STEP_BATCH, DIM, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
        stats = {}
        hnn.rollout(model.field, x0, t, method=method, dt=STEP_DT, stats=stats)
        if kind == "separable":   # the step calls the two halves (nfev counts each as a half)
            q, p = x0[:, :DIM // 2], x0[:, DIM // 2:]
            calls = [functools.partial(model.kinetic_gradient, p), functools.partial(model.potential_gradient, q)]
            calls *= stats["nfev"]
        else:
            calls = [functools.partial(model.time_derivative, x0)] * stats["nfev"]

        def field_calls(calls=calls):
            with torch.no_grad(), hnn.modes.frozen_weights():
                for call in calls:
                    call()
        timed = {"step": [], "calls": []}
        for _ in range(repeats):
            step = functools.partial(hnn.rollout, model.field, x0, t, method=method, dt=STEP_DT)
            for name, fn in (("step", step), ("calls", field_calls)):
                tic = time.perf_counter()
                fn()
                timed[name].append((time.perf_counter() - tic) / steps * 1e6)
        graph_us = None
        if method in ("leapfrog", "midpoint"):   # what the README's snippet cost before: a graph through every step
            tic = time.perf_counter()
            hnn.rollout(model.field, x0, t, method=method, dt=STEP_DT, differentiable=True)
            graph_us = (time.perf_counter() - tic) / steps * 1e6
        step_us, calls_us = statistics.median(timed["step"]), statistics.median(timed["calls"])
        rows.append({"method": method, "kind": kind, "step_us": step_us, "field_calls_per_step": stats["nfev"] / steps,
                     "field_calls_us": calls_us, "ratio": step_us / calls_us, "differentiable_step_us": graph_us})
    return rows


def _error(traj: torch.Tensor, reference: torch.Tensor) -> float:
    return float((traj - reference).abs().max())


def _timed(fn, repeats: int):
    seconds, out = [], None
    for _ in range(repeats):
        tic = time.perf_counter()
        out = fn()
        seconds.append(time.perf_counter() - tic)
    return statistics.median(seconds), out


def _as_accurate(measure, tol: float, target: float):
    """``measure(rtol) -> (seconds, error)`` at the loosest of ``tol`` * 2^k (k = 3 down to -9)
    whose error is at most ``target``: ``(rtol, seconds, error)``, or None if none gets there."""
    for k in range(3, -10, -1):
        seconds, error = measure(tol * 2.0 ** k)
        if error <= target:
            return tol * 2.0 ** k, seconds, error
    return None


def adaptive_table(model: torch.nn.Module, tolerances=(1e-7, 1e-9), repeats: int = 3) -> dict:
    """dopri5 and dop853 on ``model`` (a learned 2-dim field, run in float64) against torchdiffeq and scipy."""
    model = hnn.evaluation.float64_copy(model)
    gen = torch.Generator().manual_seed(0)
    x0 = torch.rand(ADAPTIVE_STARTS, model.input_dim, generator=gen, dtype=torch.float64) * 2 - 1
    t = np.linspace(0.0, ADAPTIVE_SPAN, ADAPTIVE_POINTS)
    f = model.time_derivative
    reference = hnn.rollout(f, x0, t, scipy_method="DOP853", rtol=1e-12, atol=1e-12)
    try:
        import torchdiffeq
    except ImportError:
        torchdiffeq = None
        print("rollout benchmark: torchdiffeq is not installed (pip install hnn[bench]); its column is left out")

    measured = {}    # (method, rtol) -> (seconds, error): a setting is timed once, however often compared

    def ours(method):
        def measure(tol):
            if (method, tol) not in measured:
                seconds, traj = _timed(functools.partial(hnn.rollout, f, x0, t, method=method, rtol=tol, atol=tol),
                                       repeats)
                measured[method, tol] = seconds, _error(traj, reference)
            return measured[method, tol]
        return measure

    rows = []
    for tol in tolerances:
        row = {"rtol": tol}
        for method in ("dopri5", "dop853"):
            row[f"{method}_s"], row[f"{method}_error"] = ours(method)(tol)
        if torchdiffeq is not None:
            times = torch.as_tensor(t)

            def theirs(times=times, tol=tol):
                # with the field as fast as inside hnn.rollout (its kernel): the integrators are compared
                with torch.no_grad(), hnn.modes.frozen_weights():
                    return torchdiffeq.odeint(lambda s, x: f(x), x0, times, method="dopri5", rtol=tol, atol=tol)
            row["torchdiffeq_s"], traj = _timed(theirs, repeats)
            row["torchdiffeq_error"] = _error(traj.transpose(0, 1), reference)
            # per-row control meets each row's tolerance and no more, where one shared step (the RMS
            # over the batch) carries the easy rows along with the hard one: compare at equal error too
            for method in ("dopri5", "dop853"):
                row[f"{method}_vs_torchdiffeq"] = _as_accurate(ours(method), tol, row["torchdiffeq_error"])
        # scipy's DOP853 at this tolerance, and ours as accurate as it
        row["scipy_s"], traj = _timed(functools.partial(hnn.rollout, f, x0, t, scipy_method="DOP853", rtol=tol,
                                                        atol=tol), repeats)
        row["scipy_error"] = _error(traj, reference)
        for method in ("dopri5", "dop853"):
            row[f"{method}_vs_scipy"] = _as_accurate(ours(method), tol, row["scipy_error"])
        rows.append(row)
    return {"starts": ADAPTIVE_STARTS, "span": ADAPTIVE_SPAN, "rows": rows}


def _adaptive_markdown(a: dict) -> list[str]:
    out = [f"| adaptive, {a['starts']} starts, t in [0, {a['span']:g}], float64 | rtol = atol | seconds | "
           "max error vs DOP853 1e-12 | theirs / ours dop853 | theirs / ours dop853 at equal error |",
           "| --- | ---: | ---: | ---: | ---: | ---: |"]

    def line(name, rtol, seconds, error, *ratios):
        cells = " | ".join(f"{r:.2f}x" if r else "" for r in ratios) if ratios else " | "
        return f"| {name} | {rtol:.2g} | {seconds:.3f} | {error:.2e} | {cells} |"
    for r in a["rows"]:
        tol = r["rtol"]
        out.append(line("hnn.rollout dop853", tol, r["dop853_s"], r["dop853_error"]))
        out.append(line("hnn.rollout dopri5", tol, r["dopri5_s"], r["dopri5_error"]))
        for theirs, name in (("torchdiffeq", "torchdiffeq.odeint dopri5"), ("scipy", "scipy solve_ivp DOP853")):
            if f"{theirs}_s" not in r:
                continue
            equal = r[f"dop853_vs_{theirs}"]
            out.append(line(name, tol, r[f"{theirs}_s"], r[f"{theirs}_error"], r[f"{theirs}_s"] / r["dop853_s"],
                            r[f"{theirs}_s"] / equal[1] if equal else None))
            for method in ("dop853", "dopri5"):
                if r[f"{method}_vs_{theirs}"]:
                    rtol, seconds, error = r[f"{method}_vs_{theirs}"]
                    out.append(line(f"hnn.rollout {method}, as accurate as {theirs}", rtol, seconds, error))
    return out


def markdown(result: dict) -> str:
    """The three tables, as docs/speed.md shows them."""
    out = ["| field call (no graph) | width | dtype | states | call (us) | its products alone (us) | call / floor "
           "| fastest rounds |", "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: |"]
    for r in result["field"]:
        out.append(f"| {r['kind']} | {r['width']} | {r['dtype']} | {r['batch']} | {r['call_us']:.1f} | "
                   f"{r['floor_us']:.1f} | {r['ratio']:.2f}x | {r['best_ratio']:.2f}x |")
    out += ["", f"| fixed-step method ({STEP_BATCH} float64 states, width {STEP_WIDTH}) | model | step (us) "
            "| field calls a step | those calls alone (us) | step / calls | with differentiable=True (us a step) |",
            "| --- | --- | ---: | ---: | ---: | ---: | ---: |"]
    for r in result["step"]:
        graph = f"{r['differentiable_step_us']:.0f}" if r["differentiable_step_us"] else ""
        out.append(f"| {r['method']} | {r['kind']} | {r['step_us']:.0f} | {r['field_calls_per_step']:.2f} | "
                   f"{r['field_calls_us']:.0f} | {r['ratio']:.2f}x | {graph} |")
    out += ["", *_adaptive_markdown(result["adaptive"])]
    return "\n".join(out)


def job_rollout(model: torch.nn.Module, rounds: int, repeats: int) -> dict:
    """All three tables at one torch thread (restored after); ``model`` is the trained spring HNN."""
    with torch_threads(1):
        result = {"field": field_table(rounds)}
        print("rollout: field table done", flush=True)
        result["step"] = step_table(repeats)
        print("rollout: step table done", flush=True)
        result["adaptive"] = adaptive_table(model, repeats=repeats)
    result["table"] = markdown(result)
    result["checks"] = []
    return result
