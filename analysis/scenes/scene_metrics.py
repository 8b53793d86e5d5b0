"""The numbers of the scene study (``analysis/scene_study.py``), one function per metric.

- ``rollout_errors``: the rollout relative error e(t) = |x_model(t) - x_true(t)| / (|x_model(t)| +
  |x_true(t)|) of each trajectory (Finzi et al. 2020), its geometric mean over the output times
  after t = 0, and the valid prediction time, the first time e(t) exceeds ``VALID_ERROR``.
- ``divergence_time``: when the true system itself, started 1e-4 away, leaves ``VALID_ERROR``:
  no model can be valid for longer on a chaotic scene.
- ``speed_at_accuracy``: every ``hnn.rollout`` setting of a ladder, timed and scored against a
  float64 DOP853 rtol 1e-12 rollout of the same field; the fastest that reaches ``TARGET``.
- ``long_drift``: the drift of the learned H (or the true energy) over many periods at one setting,
  integrated in chunks and stopped at a wall-time budget (then it says how far it got).
- ``dhnn_protocol``: the real-pendulum numbers as the D-HNN paper measured them.

Every rollout here runs on a float64 copy of the model, so tight tolerances measure the field,
not float32 rounding. States ``x = [q, p]`` of shape ``(batch, 2n)``; times in the scene's units.
"""
from __future__ import annotations

import math
import time
import warnings

import numpy as np
import torch

import hnn
from hnn.metrics import energy_drift, relative_error, summarize_errors

from hnn_analysis.integrator_study import settings

PERTURBATION = 1e-4        # the size of the start-state perturbation of the truth's own divergence
TARGET = 1e-4              # the accuracy a rollout setting must reach against its field's reference
REFERENCE = {"method": "solve_ivp", "scipy_method": "DOP853", "rtol": 1e-12, "atol": 1e-12}
# the rollout-error metric's integrator: the errors it measures are 1e-3 and up, so rtol 1e-6
# changes them in the third digit at most (checked against rtol 1e-9)
# at half the cost; a healthy field needs under 5000 steps over the horizon (3-body baseline: 4800),
# while a learned orbit that collapses shrinks the step without end: 20000 steps bound it
# the adaptive solvers' setting in the ladder: solve_ivp with DOP853, its high-order method
ADAPTIVE = {"solve_ivp": ({"scipy_method": "DOP853"},)}
EVAL_ROLLOUT = {"method": "dopri5", "rtol": 1e-6, "atol": 1e-8, "max_iterations": 20_000}


def quiet_rollout(f, x0, t, **options) -> torch.Tensor:
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")     # float64 states: the tolerances here are within reach
        return hnn.rollout(f, x0, t, **options)


def model_rollout(f, x0: torch.Tensor, t: np.ndarray, options: dict = EVAL_ROLLOUT) -> tuple[torch.Tensor, int]:
    """``(trajectories, how many blew up)``: ``hnn.rollout`` with ``options`` (default ``EVAL_ROLLOUT``;
    a learned map takes none: it steps itself) of the batch, or trajectory by trajectory when the batch
    fails; a trajectory that blows up or does not finish within its step budget counts as unrelated to
    the truth (error ~1) over the whole horizon."""
    try:
        return quiet_rollout(f, x0, t, **options), 0
    except hnn.DivergenceError:
        pass
    rows, failed = [], 0
    for i in range(len(x0)):
        try:
            rows.append(quiet_rollout(f, x0[i:i + 1], t, **options)[0])
        except hnn.DivergenceError:
            failed += 1
            # a finite stand-in far from any true state: e(t) ~ 1 for the whole trajectory
            rows.append(torch.full((len(t), x0.shape[1]), 1e6, dtype=x0.dtype))
    return torch.stack(rows), failed


def rollout_errors(f, truth: torch.Tensor, t: np.ndarray, options: dict = EVAL_ROLLOUT) -> dict:
    """``summarize_errors`` of the model field ``f`` (or a learned map, ``options`` empty) started from
    ``truth[:, 0]`` against ``truth``, plus ``seconds``, the wall time of that rollout (the rollout cost
    of the Pareto plots)."""
    tic = time.perf_counter()
    pred, failed = model_rollout(f, truth[:, 0], t, options)
    seconds = time.perf_counter() - tic
    out = summarize_errors(relative_error(pred, truth), t)
    out.update(blew_up=failed, seconds=seconds)
    return out


def divergence_time(dynamics, x0: torch.Tensor, t: np.ndarray, seed: int = 0,
                    truth: torch.Tensor | None = None) -> dict:
    """When the truth from ``x0 + PERTURBATION * (random unit vector)`` leaves ``VALID_ERROR`` of the
    truth from ``x0`` (median over starts; the horizon if never). ``truth``: the ``REFERENCE``
    rollout from ``x0`` over ``t``, if the caller has it already."""
    rng = np.random.default_rng(seed)
    direction = rng.standard_normal(tuple(x0.shape))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    a = quiet_rollout(dynamics, x0, t, **REFERENCE) if truth is None else truth
    b = quiet_rollout(dynamics, x0 + PERTURBATION * torch.as_tensor(direction, dtype=x0.dtype), t, **REFERENCE)
    s = summarize_errors(relative_error(b, a), t)
    return {"divergence_time": s["valid_time"], "divergence_times": s["valid_times"], "horizon": s["horizon"]}


# ----------------------------------------------------------------------------------------------
# speed at equal accuracy


# the adaptive solvers' tolerances of the speed study; --quick: its own, and the QUICK_DTS coarsest of
# every other step size (the finest cost the most: a smoke run's ladder stops short)
RTOLS, QUICK_RTOLS, QUICK_DTS = (1e-4, 1e-6, 1e-8, 1e-10), (1e-4, 1e-7), 3


def settings_ladder(dts, separable: bool, quick: bool, energy: bool = False) -> list[dict]:
    """The ``hnn.rollout`` settings tried: adaptive ones by tolerance, fixed-step ones by ``dt``.

    Leapfrog and yoshida4 on leapfrog are exact symplectic methods only for a separable H, so
    they are tried for separable fields only; every field gets rk4, the implicit midpoint and
    yoshida4 on it; a field that carries its H (``energy``) the discrete gradient too. yoshida4
    on the midpoint costs three midpoint solves a step (~30 field calls), so it takes only the four coarsest steps: being of order 4 it reaches 1e-4 there or not at all
    within this study's time.
    """
    rtols = QUICK_RTOLS if quick else RTOLS
    dts = dts[::2][:QUICK_DTS] if quick else dts
    # every registered solver that applies (settings.solver_settings reads hnn.SOLVERS)
    out = [options for _, options in settings.solver_settings(separable, rtols, dts, ADAPTIVE, energy)]
    if separable:       # the any-H settings too (yoshida4 on the midpoint), as for a learned H
        out += [options for _, options in settings.solver_settings(False, (), dts)
                if options not in out and "base" in options]
    return [o for o in out if o.get("base") != "midpoint" or o["dt"] in dts[:4]]


def describe(options: dict) -> str:
    """E.g. ``'rk4 dt=0.05'``, ``'yoshida4/leapfrog dt=0.1'``, ``'DOP853 rtol=1e-06'``."""
    name = options.get("scipy_method", options["method"])
    if "base" in options:
        name += "/" + options["base"]
    return f"{name} dt={options['dt']:g}" if "dt" in options else f"{name} rtol={options['rtol']:g}"


def speed_at_accuracy(f, x0: torch.Tensor, t: np.ndarray, ladder: list[dict], repeats: int = 3) -> dict:
    """Every setting of ``ladder`` (each method's from coarse to fine, stopping at the first that
    reaches ``TARGET``) scored by its max relative error over the batch and times against
    ``REFERENCE`` of the same field ``f`` (the median of ``repeats`` timings); ``{"rows", "fastest",
    "fastest_symplectic", "fastest_energy_preserving"}``, the last three the quickest settings reaching
    ``TARGET`` of any solver, of a symplectic one and of one that keeps the field's H (None when none does)."""
    reference = quiet_rollout(f, x0, t, **REFERENCE)
    rows, reached = [], set()
    for options in ladder:
        family = (options["method"], options.get("scipy_method"), options.get("base"))
        if family in reached:
            continue        # the ladder goes from coarse to fine: a finer setting of it is only slower
        solver = hnn.get_solver(options["method"])
        row = {"setting": describe(options), "options": options, "symplectic": solver.symplectic,
               "energy_preserving": solver.energy_preserving}
        try:
            seconds, traj, stats = settings.timed_rollout(f, x0, t, options, repeats, enough=0.5)
        except hnn.DivergenceError as err:
            row.update(status=type(err).__name__)
            rows.append(row)
            continue
        row.update(status="ok", seconds=seconds, nfev=stats.get("nfev"),
                   error=float(relative_error(traj, reference).max()))
        rows.append(row)
        if row["error"] <= TARGET:
            reached.add(family)
    ok = sorted((r for r in rows if r["status"] == "ok" and r["error"] <= TARGET), key=lambda r: r["seconds"])
    return {"rows": rows, "fastest": ok[0] if ok else None,
            "fastest_symplectic": next((r for r in ok if r["symplectic"]), None),
            "fastest_energy_preserving": next((r for r in ok if r["energy_preserving"]), None)}


def long_drift(f, energy, x0: torch.Tensor, options: dict, period: float, periods: int,
               budget: float, points_per_period: int = 4) -> dict:
    """Max |E(t) - E(0)| / |E(0)| over ``periods`` periods at one setting, with ``energy`` the learned
    H (or the true one); integrated ``chunk`` periods at a time, stopping once ``budget`` seconds are
    spent (``periods_done`` says how far it got). ``seconds_per_period`` is the rollout's cost."""
    chunk = max(1, periods // 50)
    t_chunk = np.linspace(0.0, chunk * period, chunk * points_per_period + 1)
    with torch.no_grad():
        e0 = energy(x0).double()
    x, drift, done, spent = x0, 0.0, 0, 0.0
    while done < periods and spent < budget:
        tic = time.perf_counter()
        try:
            traj = quiet_rollout(f, x, t_chunk, **options)
        except hnn.DivergenceError:
            return {"drift": math.inf, "periods_done": done, "seconds": spent, "blew_up": True,
                    "seconds_per_period": spent / max(done, 1)}
        spent += time.perf_counter() - tic
        with torch.no_grad():
            e = energy(traj.reshape(-1, traj.shape[-1])).reshape(traj.shape[:2]).double()
        drift = max(drift, energy_drift(e, e0, relative=True))
        x, done = traj[:, -1], done + chunk
    return {"drift": drift, "periods_done": done, "periods": periods, "seconds": spent, "blew_up": False,
            "seconds_per_period": spent / max(done, 1)}


# ----------------------------------------------------------------------------------------------
# the real pendulum as the D-HNN paper measured it


def dhnn_protocol(system, models: dict, dataset: dict) -> dict:
    """The D-HNN paper's real-pendulum numbers of each model, on its split (``split='dhnn'``):

    - test vector-field MSE over every test row and both components (± std / sqrt(rows));
    - energy MSE: each model rolled out from the first test state over the test times with
      solve_ivp's defaults (RK45, rtol 1e-3, atol 1e-6), its energy 2.4 (1 - cos q) + p^2 compared
      with that of the measured states point by point (± std / sqrt(points));
    - the mean squared state error along that rollout (their figure's curve; not printed there).
    """
    test_x = torch.as_tensor(dataset["test_x"], dtype=torch.float64)
    test_dxdt = torch.as_tensor(dataset["test_dxdt"], dtype=torch.float64)
    t = np.asarray(dataset["test_t"], dtype=np.float64)
    t = t - t[0]
    e_true = system.hamiltonian(test_x).numpy()
    out = {}
    for label, model in models.items():
        model64 = hnn.evaluation.float64_copy(model)
        with torch.enable_grad():
            sq = (model64.time_derivative(test_x).detach() - test_dxdt).pow(2).numpy()
        traj = quiet_rollout(model64.time_derivative, test_x[:1], t, method="solve_ivp", rtol=1e-3, atol=1e-6)[0]
        e_err = (system.hamiltonian(traj).numpy() - e_true) ** 2
        x_err = (traj - test_x).pow(2).mean(-1).numpy()
        out[label] = {"test_mse": [float(sq.mean()), float(sq.std() / math.sqrt(sq.size))],
                      "energy_mse": [float(e_err.mean()), float(e_err.std() / math.sqrt(len(e_err)))],
                      "state_mse": [float(x_err.mean()), float(x_err.std() / math.sqrt(len(x_err)))]}
    return out


# the D-HNN paper's own numbers on this protocol (their models, one seed, seed 42), for the table
DHNN_PAPER = {
    "baseline": {"test_mse": (1.11e-3, 4.26e-4), "energy_mse": (1.1670e-3, 1.06e-4)},
    "hnn": {"test_mse": (1.40e-3, 1.02e-3), "energy_mse": (1.0177e-2, 7.95e-4)},
    "dissipative": {"test_mse": (9.46e-4, 1.01e-4), "energy_mse": (1.0675e-3, 1.06e-4)},
}
