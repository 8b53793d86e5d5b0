"""The work-precision study's measurements (``analysis/integrator_study/work_precision.py`` is its command):
every adaptive solver, ours and the peers', at every tolerance of a ladder on a learned field, timed in
rounds, with the seconds inside the field's calls counted apart; and ``why``, the issue's measurement
taken apart one difference at a time.
"""
from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.threads import torch_threads
from hnn_analysis import commands
from hnn_analysis.integrator_study import peer_solvers
from hnn_analysis.integrator_study.settings import start_states
from hnn_analysis.integrator_study.speed_measure import study_settings

TASKS = ("spring", "pend", "2body", "3body")    # the study's tasks whose models step the state (not a latent)
MODELS = ("hnn", "baseline")
OURS = ("dopri5", "dop853")
BATCHES = (64, 1)
RTOLS = tuple(10.0 ** (-k / 2) for k in range(6, 23))           # 1e-3 .. 1e-11
QUICK_RTOLS = (1e-4, 1e-6, 1e-8)
REFERENCE_RTOL = 1e-13
OUTPUTS = 51                                    # output times over the horizon, as the study's


class Counted:
    """A field that counts its calls, the rows it was given and the seconds spent inside it; with the field's
    numpy call where it has one (the ``numpy`` of an ``hnn.interface.EnergyField``), counted alike, as our solvers make it."""

    def __init__(self, field):
        self.field = field
        self.numpy = self._numpy if getattr(field, "numpy", None) is not None else None
        self.reset()

    def _numpy(self, y):
        tic = time.perf_counter()
        out = self.field.numpy(y)
        if out is not None:                 # else the solver calls the field itself, which counts
            self.seconds += time.perf_counter() - tic
            self.calls += 1
            self.rows += len(y)
        return out

    def reset(self):
        self.calls, self.rows, self.seconds = 0, 0, 0.0

    def __call__(self, x):
        tic = time.perf_counter()
        out = self.field(x)
        self.seconds += time.perf_counter() - tic
        self.calls += 1
        self.rows += len(x)
        return out


def solvers(peer_names=None) -> dict:
    """``{name: run(field, x0, t, rtol, atol) -> (batch, len(t), dim)}``: ours, with one step size per row and
    with ``steps='shared'`` (scipy's step rule on the batch as one system; on one state, scipy's rule on that
    row, where the default steps under the PI rule), then the installed peers."""
    ours = {f"hnn {m}": (lambda f, x0, t, rtol, atol, m=m: hnn.rollout(f, x0, t, method=m, rtol=rtol, atol=atol))
            for m in OURS}
    ours.update({f"hnn {m} shared": (lambda f, x0, t, rtol, atol, m=m: hnn.rollout(
        f, x0, t, method=m, rtol=rtol, atol=atol, steps="shared")) for m in OURS})
    return {**ours, **{peer.name: peer.run for peer in peer_solvers.available(peer_names)}}


def call_seconds(field, x0: torch.Tensor, calls: int = 300) -> float:
    """The median seconds of one call of ``field`` on ``x0`` alone, as a rollout makes it (no graph, the
    weights frozen, one thread): medians of blocks of 10."""
    with torch.no_grad(), hnn.modes.frozen_weights(), torch_threads(1):
        for _ in range(20):
            field(x0)
        blocks = []
        for _ in range(calls // 10):
            tic = time.perf_counter()
            for _ in range(10):
                field(x0)
            blocks.append((time.perf_counter() - tic) / 10)
    return statistics.median(blocks)


def measure(field, x0: torch.Tensor, t: np.ndarray, rtols, repeats: int, runners: dict) -> list[dict]:
    """Every solver of ``runners`` at every tolerance on ``field`` from ``x0``: one row each with the median
    seconds and field seconds over ``repeats`` rounds, the calls, the rows evaluated and the max error."""
    with torch.no_grad():
        reference = hnn.rollout(field, x0, t, scipy_method="DOP853", rtol=REFERENCE_RTOL, atol=REFERENCE_RTOL)
    counted = Counted(field)
    runs: dict = {}
    for run in runners.values():                # once each, untimed: first calls (imports, caches) out of the rounds
        try:
            run(counted, x0, t, rtols[0], rtols[0])
        except hnn.DivergenceError:
            pass                                # the rounds say so, at each tolerance
    # rounds, and in each the solvers one after another at each tolerance: a drift in the box's load then
    # meets the solvers compared at one error level within a fraction of a second of each other
    for _ in range(repeats):
        for rtol in rtols:
            for name, run in runners.items():
                if runs.get((name, rtol), {}).get("status", "ok") != "ok":
                    continue                    # diverged in an earlier round: the same again (deterministic)
                counted.reset()
                tic = time.perf_counter()
                try:
                    traj = run(counted, x0, t, rtol, rtol)
                except hnn.DivergenceError as err:
                    runs[name, rtol] = {"status": f"DivergenceError: {str(err).split('.')[0]}"}
                    continue
                seconds = time.perf_counter() - tic
                got = runs.setdefault((name, rtol), {"status": "ok", "seconds": [], "field_s": []})
                got["seconds"].append(seconds)
                got["field_s"].append(counted.seconds)
                got.update(calls=counted.calls, rows=counted.rows, error=float((traj - reference).abs().max()))
    rows = []
    for (name, rtol), got in runs.items():
        row = {"solver": name, "rtol": rtol, **got}
        if got["status"] == "ok":     # each round's seconds too: the report pairs the solvers round by round
            row["round_seconds"] = got["seconds"]
            row["seconds"], row["field_s"] = statistics.median(got["seconds"]), statistics.median(got["field_s"])
        rows.append(row)
    return rows


def _model(task: str, label: str, runs: Path):
    args = hnn.tasks.task_config(task, {"save_dir": str(runs), "seed": 0, "model": label})
    found = hnn.runs.find_run(args)
    return None if found is None else hnn.evaluation.float64_copy(hnn.load_run(found)[0])


def measure_task(task: str, runs: Path, rtols, repeats: int, notes: list, models=MODELS, peer_names=None) -> list[dict]:
    """The rows of ``task``'s saved models (``models``) at each of ``BATCHES``."""
    cfg = study_settings(task)
    t = np.linspace(0.0, cfg["T"], OUTPUTS)
    starts = start_states(task, hnn.load_task(task), max(BATCHES))
    out = []
    for label in models:
        model = _model(task, label, runs)
        if model is None:
            notes.append(f"{task} {label}: no saved run in {commands.portable_path(runs)} (train it with "
                         "analysis/reproduce.py); skipped")
            print(f"  {task} {label}: not found, skipped", flush=True)
            continue
        for batch in BATCHES:
            x0 = starts[:batch]
            tic = time.perf_counter()
            rows = measure(model.field, x0, t, rtols, repeats, solvers(peer_names))
            call_us = call_seconds(model.field, x0) * 1e6
            for row in rows:
                row.update(task=task, model=label, batch=batch, call_us=call_us, span=float(t[-1]))
            out += rows
            print(f"  {task} {label} batch {batch}: {len(rows)} settings in {time.perf_counter() - tic:.0f} s",
                  flush=True)
    return out


# ------------------------------------------------------------------------- why: the measurement

_DP_B_HAT = (5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40)  # Dormand-Prince's 4th order


def _row_worst_rms(error: torch.Tensor) -> torch.Tensor:
    """torchdiffeq's ``norm`` option: the largest RMS of one trajectory, so the worst row sets the step."""
    return error.pow(2).mean(-1).sqrt().max()


def why(runs: Path, rtols=(1e-7, 1e-9)) -> dict | None:
    """The learned spring HNN as the issue measured it, each difference between torchdiffeq's dopri5 and
    ours tried alone: field calls, rows evaluated and max error (deterministic: no timings)."""
    model = _model("spring", "hnn", runs)
    if model is None:
        return None
    x0 = torch.rand(64, 2, generator=torch.Generator().manual_seed(0), dtype=torch.float64) * 2 - 1
    t = np.linspace(0.0, 30.0, 100)
    field = model.field
    reference = hnn.rollout(field, x0, t, scipy_method="DOP853", rtol=REFERENCE_RTOL, atol=REFERENCE_RTOL)
    counted = Counted(field)
    variants = {
        "hnn dopri5: one step size per row, Dormand-Prince's estimator and dense output":
            lambda rtol: hnn.rollout(counted, x0, t, method="dopri5", rtol=rtol, atol=rtol),
        "scipy RK45, each row alone (64 calls)":
            lambda rtol: torch.cat([peer_solvers.PEERS["scipy RK45"].run(counted, x0[i:i + 1], t, rtol, rtol)
                                    for i in range(len(x0))]),
        "scipy RK45 on the batch: one step, RMS over the batch":
            lambda rtol: peer_solvers.PEERS["scipy RK45"].run(counted, x0, t, rtol, rtol),
    }
    if peer_solvers.PEERS["torchdiffeq dopri5"].available():
        import torchdiffeq
        from torchdiffeq._impl import dopri5 as tde

        def odeint(rtol, estimator=None, **options):
            solver = tde.Dopri5Solver
            own = solver.tableau
            if estimator is not None:           # b - b_hat of the 4th-order formula given, for one run
                b = own.c_sol.to(torch.float64)
                solver.tableau = own._replace(c_error=b - torch.tensor(estimator, dtype=torch.float64))
            try:
                with torch.no_grad(), hnn.modes.frozen_weights(), torch_threads(1):
                    return torchdiffeq.odeint(lambda s, x: counted(x), x0, torch.as_tensor(t), method="dopri5",
                                              rtol=rtol, atol=rtol, options=options).transpose(0, 1)
            finally:
                solver.tableau = own
        variants.update({
            "torchdiffeq dopri5 as it comes: RMS over the batch, Shampine's estimator, a quartic through the midpoint":
                lambda rtol: odeint(rtol),
            "torchdiffeq, the worst row's RMS as its norm (its norm option)":
                lambda rtol: odeint(rtol, norm=_row_worst_rms),
            "torchdiffeq with Dormand-Prince's estimator (as scipy and ours)":
                lambda rtol: odeint(rtol, estimator=_DP_B_HAT),
            "torchdiffeq stepping onto every output time (its step_t option)":
                lambda rtol: odeint(rtol, step_t=torch.as_tensor(t)),
        })
    rows = []
    for rtol in rtols:
        for name, run in variants.items():
            counted.reset()
            error = float((run(rtol) - reference).abs().max())
            rows.append({"variant": name, "rtol": rtol, "calls": counted.calls, "rows": counted.rows, "error": error})
    return {"starts": len(x0), "span": float(t[-1]), "outputs": len(t), "rows": rows}
