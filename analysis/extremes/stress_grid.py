"""The stress study's grid: every kind fit on two scenes at the extremes of units, masses and precision,
and the nominal models' rollouts at long horizons and large steps (the scenes, cells and outcomes are
described in ``analysis/stress.py``, its command)."""
from __future__ import annotations

import concurrent.futures
import math
import multiprocessing
import time
import warnings

import numpy as np
import torch

import hnn
from hnn.balance import balance_weights
from hnn.integrators.stability import StepSizeWarning
from hnn.threads import torch_threads
from hnn_analysis import plan

arm_data = hnn.load_task("arm")
CANONICAL = ("hnn", "baseline", "separable", "dissipative", "mechanical")
VELOCITY = ("second_order",)
KINDS = CANONICAL + VELOCITY
BUDGET = {"steps": 600, "hidden": 64, "rows": 500, "learn_rate": 3e-3}
QUICK = {"steps": 150, "hidden": 32, "rows": 200, "learn_rate": 1e-2}
PRECISION_SEEDS = (0, 1, 2)
# an error at or above this is no fit (a zero field scores 1), whatever its nominal: never "works"
NO_FIT = 0.5
HORIZON, QUICK_HORIZON = 100_000, 1_000
# row -> (scale of q, of p, of t, float64, mass ratio)
CELLS = {"nominal": (1, 1, 1, False, 1), "q x1e-3": (1e-3, 1e3, 1, False, 1), "q x1e3": (1e3, 1e-3, 1, False, 1),
         "p x1e-3": (1, 1e-3, 1, False, 1), "p x1e3": (1, 1e3, 1, False, 1), "t x1e-3": (1, 1, 1e-3, False, 1),
         "t x1e3": (1, 1, 1e3, False, 1), "float64": (1, 1, 1, True, 1), "mass ratio 1e3": (1, 1, 1, False, 1e3)}
# the same scenes trained with the rescaling of ``--units on`` (hnn.units): the cell's data, its scales
# fit from them, the network trained in those units and its field read back in the cell's
UNITS_ON = ", --units on"
RESCALED = {f"{cell}{UNITS_ON}": cell for cell in ("nominal", "q x1e-3", "q x1e3", "p x1e-3", "p x1e3", "t x1e-3",
                                                   "t x1e3")}
QUICK_CELLS = ("nominal", "p x1e3", f"p x1e3{UNITS_ON}", "t x1e-3", "mass ratio 1e3")


def _spring(rows: int, seed: int, mass_ratio: float) -> dict:
    """Canonical states and dx/dt of the spring (m = mass_ratio, k = 1), float64, and its [q, qdot] twin."""
    g = torch.Generator().manual_seed(seed)
    m = float(mass_ratio)
    x = torch.randn(rows, 2, generator=g, dtype=torch.float64) * torch.tensor([1.0, math.sqrt(m)], dtype=torch.float64)
    dx = torch.stack([x[:, 1] / m, -x[:, 0]], 1)
    z = torch.stack([x[:, 0], x[:, 1] / m], 1)
    return {"x": x, "dxdt": dx, "z": z, "dzdt": torch.stack([z[:, 1], -x[:, 0] / m], 1), "periodic": False}


def _arm(rows: int, seed: int, mass_ratio: float) -> dict:
    arm = arm_data.Arm((1.0, float(mass_ratio)))
    x = arm_data.sample_states(arm, rows, torch.Generator().manual_seed(seed))
    dx = arm.dynamics(x)
    z, dz = torch.func.jvp(arm.velocities, (x,), (dx,))        # d/dt [q, qdot] along the flow
    return {"x": x, "dxdt": dx, "z": z, "dzdt": dz, "periodic": True}


SCENES = {"spring": _spring, "arm": _arm}


def _in_units(data: dict, cq: float, cp: float, ct: float) -> dict:
    """The scene's arrays in units where q, p and t read ``cq``, ``cp``, ``ct`` times their values."""
    n = data["x"].shape[1] // 2
    xs = torch.tensor([cq] * n + [cp] * n, dtype=torch.float64)
    zs = torch.tensor([cq] * n + [cq / ct] * n, dtype=torch.float64)
    return {**data, "x": data["x"] * xs, "dxdt": data["dxdt"] * xs / ct, "z": data["z"] * zs, "dzdt": data["dzdt"] * zs / ct}


def field_error(pred: torch.Tensor, true: torch.Tensor) -> float:
    """Mean over components of |pred_j - true_j| / |true_j| (column norms): the same in any units."""
    return float(((pred - true).norm(dim=0) / true.norm(dim=0)).mean())


def fit(kind: str, scene: str, cell: str, budget: dict, seed: int = 0) -> tuple[object, dict]:
    """``(model, row)``: ``kind`` trained on ``scene`` under ``cell`` (a key of ``CELLS`` or ``RESCALED``);
    the row has its error or its stop."""
    rescaled = cell in RESCALED
    cq, cp, ct, wide, ratio = CELLS[RESCALED.get(cell, cell)]
    data = {split: _in_units(SCENES[scene](budget["rows"], seed + offset, ratio), cq, cp, ct)
            for split, offset in (("train", 0), ("test", 1))}
    x_key, y_key = ("z", "dzdt") if kind in VELOCITY else ("x", "dxdt")
    dtype = torch.float64 if wide else torch.float32
    torch.manual_seed(seed)
    model = hnn.kinds.model_from_args({"kind": kind, "input_dim": data["train"]["x"].shape[1], "periodic":
                                       data["train"]["periodic"], "hidden_dim": budget["hidden"],
                                       "dtype": "float64" if wide else "float32"})
    x, y = (data["train"][k].to(dtype) for k in (x_key, y_key))
    row = {"kind": kind, "scene": scene, "cell": cell}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if rescaled:        # --units on: train in the data's canonical units, answer in the cell's
                coordinates = "velocity" if kind in VELOCITY else "canonical"
                # a kind that reads q as angles (cos q, sin q) keeps the radian: s_q = 1
                scales = hnn.units.fit_scales(x, y, coordinates, getattr(model, "periodic", False))
                x, y = (torch.as_tensor(a, dtype=dtype) for a in scales.to_canonical(x, y, coordinates))
                inner, model = model, hnn.units.Rescaled(model, scales).to(dtype)
                row["scales"] = scales.to_dict()
            hnn.train(inner if rescaled else model, x, y, total_steps=budget["steps"], learn_rate=budget["learn_rate"],
                      seed=seed, progress=False, loss_weights=balance_weights(y, "auto"), threads=None)
            with torch.no_grad():
                pred = model.time_derivative(data["test"][x_key].to(dtype)).double()
            row["error"] = field_error(pred, data["test"][y_key])
        except (hnn.DivergenceError, ValueError) as err:
            row["stop"] = f"{type(err).__name__}: {str(err)[:240]}"
    row["warned"] = sorted({str(w.message).split(" is far")[0] for w in caught if "far from unit scale" in str(w.message)})
    return model, row


def _spring_energy(states: torch.Tensor) -> torch.Tensor:
    """The true energy of spring states ``(..., 2)`` (m = k = 1: the same in [q, p] and [q, qdot])."""
    return 0.5 * (states[..., 0] ** 2 + states[..., 1] ** 2)


def energy_change(model, kind: str, steps: int, dt: float, seed: int = 0) -> dict:
    """Largest relative change of the spring's true energy along the model's RK4 rollout from 4 starts."""
    x0 = torch.randn(4, 2, generator=torch.Generator().manual_seed(seed + 7), dtype=torch.float64)
    param = next(model.parameters())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StepSizeWarning)
        try:
            path = hnn.rollout(model.time_derivative, x0.to(param.dtype), dt * np.arange(steps + 1), method="rk4")
            E = _spring_energy(path.double())
            row = {"error": float(((E - E[:, :1]).abs() / E[:, :1]).max())}
        except hnn.DivergenceError as err:
            row = {"stop": f"DivergenceError: {str(err)[:240]}"}
    if any(issubclass(w.category, StepSizeWarning) for w in caught):
        row["warned"] = ["dt past RK4's stability limit"]
    return row


def outcome(row: dict, nominal: dict | None) -> str:
    off_scale = [w for w in row.get("warned", ()) if not w.startswith("dt")]
    said = ([f"{', '.join(off_scale)} off unit scale"] if off_scale else []) + [w for w in row.get("warned", ())
                                                                               if w.startswith("dt")]
    warned = f" (warned: {'; '.join(said)})" if said else ""
    if "stop" in row:
        return f"stops: {row['stop']}{warned}"
    if nominal is None or "error" not in nominal:
        return f"{row['error']:.3g}{warned}"
    factor = row["error"] / max(nominal["error"], 1e-300)
    word = "works" if factor <= 2 and row["error"] < NO_FIT else "degrades"
    return f"{word} {row['error']:.3g} ({factor:.2g}x){warned}"


def _fit_row(kind: str, scene: str, cell: str, budget: dict, seed: int) -> dict:
    """One grid cell's row, its seconds included (a worker's task)."""
    tic = time.perf_counter()
    row = fit(kind, scene, cell, budget, seed)[1]
    return {**row, "seconds": time.perf_counter() - tic}


def _rollout_rows(kind: str, budget: dict, horizon: int, seed: int) -> list[dict]:
    """The spring's nominal ``kind`` (trained again: a fit is deterministic at one thread) rolled out
    over ``horizon`` and 1000 steps and at omega dt 0.1, 2.5, 3.0 (a worker's task)."""
    model = fit(kind, "spring", "nominal", budget, seed)[0]
    short = energy_change(model, kind, 1000, 0.1, seed)
    rows = [{"kind": kind, "cell": "horizon 1,000 steps (nominal)", **short},
            {"kind": kind, "cell": f"horizon {horizon:,} steps", "nominal": short,
             **energy_change(model, kind, horizon, 0.1, seed)}]
    base = energy_change(model, kind, 100, 0.1, seed)
    rows.append({"kind": kind, "cell": "omega dt 0.1 (nominal)", **base})
    for wdt in (2.5, 3.0):
        rows.append({"kind": kind, "cell": f"omega dt {wdt}", "nominal": base, **energy_change(model, kind, 100, wdt, seed)})
    return rows


def _worker_start() -> None:
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")     # a fit records its own warnings; the rest would repeat per task


def _call(task: tuple):
    function, arguments = task
    return function(*arguments)


def _describe(task: tuple) -> str:
    function, arguments = task
    if function is _fit_row:
        return " ".join(map(str, arguments[:3]))
    return f"{arguments[0]} rollouts" if function is _rollout_rows else "precision"


# a plan's measurement of a fit: this many steps of each kind's nominal fit on each scene, and a rollout of this many
# steps of the spring's (their cost per step times the grid's steps, horizons and precision fits)
PLAN_STEPS, PLAN_ROLLOUT = 60, 2000


def plan_stages(quick: bool, seed: int = 0, jobs: int = 1) -> list:
    """The grid's stages for a plan (``analysis/plan.py``), each estimated from short fits and a rollout of
    every kind measured now, on one thread: the fits, the rollouts (1000 steps and the horizon), the
    precision part; the fits and rollouts shared over ``jobs`` workers."""
    budget, horizon = (QUICK, QUICK_HORIZON) if quick else (BUDGET, HORIZON)
    kinds = ("hnn", "mechanical") if quick else KINDS
    cells = QUICK_CELLS if quick else tuple(CELLS) + tuple(RESCALED)
    fit_seconds, roll_seconds = {}, {}

    def timed_fit(kind, scene, steps):
        tic = time.perf_counter()
        model = fit(kind, scene, "nominal", {**budget, "steps": steps}, seed)[0]
        return model, time.perf_counter() - tic
    with torch_threads(1), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for scene in SCENES:
            for kind in kinds:
                # the data, the model and a first step (twice: the first call of a kind pays its one-time costs),
                # then PLAN_STEPS more: a fit's cost is the setup and its steps at that pace
                setup = min(timed_fit(kind, scene, 0)[1] for _ in range(2))
                model, seconds = timed_fit(kind, scene, PLAN_STEPS)
                fit_seconds[kind, scene] = setup + max(seconds - setup, 0.0) * budget["steps"] / PLAN_STEPS
                if scene == "spring":
                    tic = time.perf_counter()
                    energy_change(model, kind, PLAN_ROLLOUT, 0.1, seed)
                    # the task trains the model again, then rolls it out over 1000, the horizon and 4 x 100 steps
                    roll_seconds[kind] = fit_seconds[kind, scene] + (time.perf_counter() - tic) * (
                        1400 + horizon) / PLAN_ROLLOUT
    fits = [fit_seconds[kind, scene] for scene in SCENES for kind in kinds for _ in cells]
    tasks = fits + list(roll_seconds.values())
    stages = [plan.Stage("fit", len(fits), f"cells x kinds x scenes, {budget['steps']} steps each",
                         plan.schedule(tasks, jobs), f"{PLAN_STEPS} steps and a {PLAN_ROLLOUT}-step rollout of each "
                         f"kind timed now, with the kinds' rollouts, on {jobs} worker{'s' if jobs > 1 else ''}")]
    if not quick:       # one worker's task: 12 spring fits of the HNN, float32 and float64, 1 and 2 threads
        stages.append(plan.Stage("precision", 4 * len(PRECISION_SEEDS), "fits", 4 * len(PRECISION_SEEDS)
                                 * fit_seconds["hnn", "spring"], "the HNN's spring fit timed now"))
    return stages


def run(quick: bool, seed: int = 0, jobs: int = 1) -> dict:
    """The grid, the rollouts and (unless ``quick``) the precision part, here (``jobs`` 1) or in ``jobs``
    worker processes, the longest tasks first (the mechanical kind's 10^5-step rollout alone is a third
    of the default's CPU time). Each task seeds its own fit, so the numbers do not depend on ``jobs``."""
    budget, horizon = (QUICK, QUICK_HORIZON) if quick else (BUDGET, HORIZON)
    kinds = ("hnn", "mechanical") if quick else KINDS
    cells = QUICK_CELLS if quick else tuple(CELLS) + tuple(RESCALED)
    fits = [(_fit_row, (kind, scene, cell, budget, seed)) for scene in SCENES for kind in kinds for cell in cells]
    rollouts = [(_rollout_rows, (kind, budget, horizon, seed)) for kind in sorted(kinds, key=lambda k: k != "mechanical")]
    tasks = rollouts + ([] if quick else [(precision, (budget,))]) + fits
    results = [None] * len(tasks)
    progress = hnn.sweep.Progress(len(tasks))
    if jobs <= 1:
        for i, task in enumerate(tasks):
            results[i] = _call(task)
            print(f"{progress.advance()} {_describe(task)}", flush=True)
    else:
        context = multiprocessing.get_context("spawn")     # a fresh interpreter: no torch state copied by fork
        with concurrent.futures.ProcessPoolExecutor(jobs, mp_context=context, initializer=_worker_start) as pool:
            running = {pool.submit(_call, task): i for i, task in enumerate(tasks)}
            for future in concurrent.futures.as_completed(running):
                results[running[future]] = future.result()
                print(f"{progress.advance()} {_describe(tasks[running[future]])}", flush=True)
    rolled = sorted((row for rows in results[:len(rollouts)] for row in rows), key=lambda row: kinds.index(row["kind"]))
    return {"rows": results[-len(fits):], "rollouts": rolled,
            "budget": budget, "horizon": horizon, "seed": seed, "precision": [] if quick else results[len(rollouts)]}


def precision(budget: dict) -> list[dict]:
    """The HNN on the spring at each of ``PRECISION_SEEDS``, float32 and float64, on 1 and 2 torch threads."""
    out = []
    for wide in (False, True):
        for threads in (1, 2):
            with torch_threads(threads):
                for seed in PRECISION_SEEDS:
                    _, row = fit("hnn", "spring", "float64" if wide else "nominal", budget, seed)
                    out.append({"dtype": "float64" if wide else "float32", "threads": threads, "seed": seed, **row})
    return out
