"""The stress study: every kind on two scenes at the extremes of units, masses, horizons, step sizes
and precision; each cell works (within 2x of its nominal), degrades (its number) or stops (one error).

    python analysis/stress.py [--quick] [--out results/stress] [--update-docs]     # docs/stress.md

Scenes (the truth in closed form, states drawn at random, dx/dt exact):

- ``spring``: H = p^2 / (2 m) + k q^2 / 2 (m = k = 1), q ~ N(0, 1), p ~ N(0, 1);
- ``arm``: the two-link arm of ``experiment-arm`` (1 kg, 1 m links; q in radians, read as angles).

Each kind is fit to dx/dt by ``hnn.train`` at one small budget (``BUDGET``, the default ``--balance
auto`` of the runs: ``hnn.balance``), in the coordinates it reads: canonical [q, p] (hnn, baseline,
separable, dissipative, mechanical) or [q, qdot] (second_order). Its error is unit-free: the mean
over components of |f_j - f_true_j| / |f_true_j| on held-out states. Rows (``CELLS``):

- **units**: q, p or t in units 10^-3 or 10^3 times the scene's (q' = s q with p' = p / s, so
  Hamilton's equations hold with the same H; p' = s p with H' = s H, a mass unit; t' = s t with
  H' = H / s); **float64** training; **mass** ratio 10^3 (the spring's m / k, the arm's forearm
  against its upper arm);
- **units, --units on**: the nominal and each unit change again with ``hnn.units``' rescaling: scales
  s_q, s_p, s_t fit from the cell's training data (s_q = 1 for the arm's angles), the network trained
  in q / s_q, p / s_p, t / s_t and its field read back in the cell's units;
- **horizon** (spring): the nominal model rolled out by RK4 at dt = 0.1 for ``HORIZON`` steps, the
  true energy's largest relative change along it against the same over 1000 steps;
- **dt** (spring): RK4 at omega dt = 2.5 and 3.0 (its stability limit is 2.83) over 100 steps,
  the energy change against omega dt = 0.1's.

A cell **works** if its number is within 2x of the kind's nominal, **degrades** (its number and the
factor) otherwise, **stops** when training or the rollout raised (its error's first words); a
training that warned (data far from unit scale, ``hnn.training.UNIT_SCALE``) or a rollout that warned (dt past
RK4's stability limit on the model's fastest mode: ``hnn.integrators.stability``) is marked ``(warned)``.
The LNN (``lagrangian``) and the Cartesian kinds are not in the grid: the LNN's start is its own
part (``lnn_start``), the Cartesian kinds need a constraint graph these scenes do not have.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import json
import math
import multiprocessing
import os
import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.balance import balance_weights
from hnn.integrators.stability import StepSizeWarning
from hnn_analysis import commands, pages
from hnn_analysis.provenance import machine, provenance

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
                      seed=seed, progress=False, loss_weights=balance_weights(y, "auto"))
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


def _outcome(row: dict, nominal: dict | None) -> str:
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
            torch.set_num_threads(threads)
            try:
                for seed in PRECISION_SEEDS:
                    _, row = fit("hnn", "spring", "float64" if wide else "nominal", budget, seed)
                    out.append({"dtype": "float64" if wide else "float32", "threads": threads, "seed": seed, **row})
            finally:
                torch.set_num_threads(1)
    return out


def precision_text(rows: list[dict]) -> list[str]:
    """Per dtype: each seed's error at 1 and 2 threads, their largest relative gap, the spread over seeds."""
    lines = ["**precision** (the HNN on the spring, the nominal budget: field error at seeds "
             f"{', '.join(map(str, PRECISION_SEEDS))})", "",
             "| dtype | 1 thread | 2 threads | largest gap 1 vs 2 threads, same seed | spread over seeds (max / min) |",
             "| --- | --- | --- | --- | --- |"]
    for dtype in ("float32", "float64"):
        one, two = ([r.get("error", math.nan) for r in rows if r["dtype"] == dtype and r["threads"] == t] for t in (1, 2))
        gap = max(abs(a - b) / a for a, b in zip(one, two))
        lines.append(f"| {dtype} | {', '.join(f'{e:.4g}' for e in one)} | {', '.join(f'{e:.4g}' for e in two)} | "
                     f"{gap:.2g} | {max(one) / min(one):.2g} |")
    return lines + [""]


def text(results: dict, meta: dict) -> str:
    b = results["budget"]
    jobs = f"{meta['jobs']} processes of one torch thread" if meta.get("jobs", 1) > 1 else "one torch thread"
    lines = [f"From `{meta['command']}` at commit {meta['commit']} ({machine(meta)}, {jobs}), "
             f"{meta['seconds']:.0f} s wall, {meta['cpu_seconds']:.0f} s of CPU (load average {meta['load']:.1f} at "
             f"its end, the box shared): seed {results['seed']}, {b['steps']} Adam steps at rate {b['learn_rate']}, "
             f"{b['hidden']} hidden units, {b['rows']} training and {b['rows']} test states, the default --balance auto. "
             "Field error: mean over components of |f_j - f_true_j| / |f_true_j| on the test states (a zero field "
             f"scores 1; at or above {NO_FIT} a cell never counts as working). A cell: works (within 2x of the "
             "kind's nominal), degrades (its number, its factor), stops (the error it raised).", ""]
    for scene in SCENES:
        rows = [r for r in results["rows"] if r["scene"] == scene]
        kinds = list(dict.fromkeys(r["kind"] for r in rows))
        cells = list(dict.fromkeys(r["cell"] for r in rows))
        lines += [f"**{scene}**", "", "| cell | " + " | ".join(kinds) + " |", "| --- " * (len(kinds) + 1) + "|"]
        for cell in cells:
            out = []
            for kind in kinds:
                row = next(r for r in rows if r["kind"] == kind and r["cell"] == cell)
                nominal = next(r for r in rows if r["kind"] == kind and r["cell"] == "nominal")
                out.append(_outcome(row, None if cell == "nominal" else nominal))
            lines.append(f"| {cell} | " + " | ".join(out) + " |")
        lines.append("")
    kinds = list(dict.fromkeys(r["kind"] for r in results["rollouts"]))
    cells = list(dict.fromkeys(r["cell"] for r in results["rollouts"]))
    lines += ["**spring, the nominal models' RK4 rollouts** (largest relative change of the true energy, 4 starts)", "",
              "| cell | " + " | ".join(kinds) + " |", "| --- " * (len(kinds) + 1) + "|"]
    for cell in cells:
        out = [_outcome(r, r.get("nominal")) for kind in kinds for r in results["rollouts"]
               if r["kind"] == kind and r["cell"] == cell]
        lines.append(f"| {cell} | " + " | ".join(out) + " |")
    if results.get("precision"):
        lines += [""] + precision_text(results["precision"])
    return "\n".join(lines) + "\n"


def lnn_start(bobs=(1, 3, 5), seeds: int = 5, inits=("lnn", "lnn_convex"), steps: int = 0,
              save_dir: Path = Path("results/stress/chain")) -> list[dict]:
    """The LNN on CHNN's chains as the peers' table trains it (softplus, 256 units, rate 1e-3) from each
    init: per seed the training states (of 40 paths) whose d2L/dqdot2 cannot be solved, the largest
    acceleration at them, whether the first batch's loss (200 RK4 snippets) is computed and, with
    ``steps``, whether that many training steps run."""
    from hnn.models.lagrangian import SingularLagrangianError
    out = []
    for n in bobs:
        for init in inits:
            for seed in range(seeds):
                config = hnn.tasks.task_config("chain", {"bobs": n, "model": "lagrangian", "nonlinearity": "softplus",
                                                         "learn_rate": 1e-3, "init": init, "n_train": 40, "n_test": 10,
                                                         "seed": seed, "save_dir": str(save_dir)})
                objective = config.make_objective()
                data = objective.prepare(config.dataset())
                saved = {**config.to_dict(), "kind": config.kind}
                torch.manual_seed(seed)
                model = hnn.kinds.model_from_args(saved)
                z = torch.as_tensor(data["x"][:2000], dtype=torch.float32)
                row = {"bobs": n, "init": init, "seed": seed, "states": len(z)}
                try:
                    with torch.no_grad():
                        row["max_acceleration"] = float(model.acceleration(z).abs().max())
                    row["singular"] = 0
                except SingularLagrangianError as err:
                    row["singular"] = len(err.states)
                options = objective.train_options(model, hnn.specs.run_specs(saved).objective, data)
                first = torch.as_tensor(data[objective.arrays[0]][:200], dtype=torch.float32)
                try:
                    with torch.no_grad():
                        row["first_loss"] = float(options["loss"](first, first).mean())
                except hnn.DivergenceError as err:
                    row["first_stop"] = f"{type(err).__name__}: {str(err)[:120]}"
                if steps:
                    try:
                        stats = hnn.train(model, data[objective.arrays[0]], data[objective.arrays[1]], total_steps=steps,
                                          learn_rate=config.learn_rate, weight_decay=config.weight_decay,
                                          batch_size=config.batch_size, seed=seed, optimizer=config.optimizer,
                                          schedule=config.schedule, progress=False, **options)
                        row["trained_loss"] = stats["train_loss"][-1]
                    except hnn.DivergenceError as err:
                        row["train_stop"] = f"{type(err).__name__}: {str(err)[:120]}"
                out.append(row)
                print(row, flush=True)
    return out


def lnn_start_text(rows: list[dict], meta: dict, steps: int) -> str:
    jobs = f"{meta['jobs']} processes of one torch thread" if meta.get("jobs", 1) > 1 else "one torch thread"
    lines = [f"From `{meta['command']}` at commit {meta['commit']} ({machine(meta)}, {jobs}), "
             f"{meta['seconds']:.0f} s wall, {meta['cpu_seconds']:.0f} s of CPU: CHNN's chains, the LNN as the peers' "
             "table trains it (softplus, 256 units), seeds 0 to "
             f"{max(r['seed'] for r in rows)}; each seed's own draw of the init.", "",
             "| bobs | init | seeds whose first batch failed | states with singular d2L/dqdot2 | largest acceleration "
             "at init (median over seeds, max) |" + (f" seeds that trained {steps} steps |" if steps else ""),
             "| --- | --- | --- | --- | --- |" + (" --- |" if steps else "")]
    for n in dict.fromkeys(r["bobs"] for r in rows):
        for init in dict.fromkeys(r["init"] for r in rows):
            group = [r for r in rows if r["bobs"] == n and r["init"] == init]
            failed = [r for r in group if "first_stop" in r]
            kinds = sorted({r["first_stop"].split(":")[0] for r in failed})
            acc = [r["max_acceleration"] for r in group if "max_acceleration" in r]
            cells = [str(n), init, f"{len(failed)} of {len(group)}" + (f" ({', '.join(kinds)})" if kinds else ""),
                     f"{sum(r['singular'] for r in group)} of {sum(r['states'] for r in group)}",
                     f"{np.median(acc):.3g}, {max(acc):.3g}" if acc else "-"]
            if steps:
                cells.append(f"{sum('trained_loss' in r for r in group)} of {len(group)}")
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _report(path: Path, update_docs: bool) -> dict:
    """The tables of a saved ``stress.json`` or ``lnn-start.json``, printed and (``update_docs``) written."""
    results = json.loads(path.read_text())
    if "lnn_start" in results:
        steps = int(results["meta"]["command"].split("--lnn-steps")[1].split()[0]) if "--lnn-steps" in \
            results["meta"]["command"] else 0
        name, body = "lnn-start", lnn_start_text(results["lnn_start"], results["meta"], steps)
    else:
        name, body = "stress", text(results, results["meta"])
    print(body)
    if update_docs:
        print(f"updated the {name} section of {pages.update_section(name, body)}")
    return results


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its finished workers."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    commands.add_flags(parser, quick="two kinds, four cells, 150 steps, a 1000-step horizon, no precision part "
                                     "(under a minute)",
                       out="folder for stress.json and stress.md", out_default=Path("results/stress"),
                       update_docs="write the stress section of docs/stress.md")
    parser.add_argument("--seed", type=hnn.cli.int_at_least(0), default=0, help="seed of the data and the inits")
    parser.add_argument("--jobs", type=hnn.cli.int_at_least(1), default=2,
                        help="worker processes of the grid, one torch thread each (default 2: the default grid's "
                             "CPU time over two cores; the numbers do not depend on it)")
    parser.add_argument("--lnn-start", dest="lnn_start", action="store_true",
                        help="instead of the grid: the LNN's start on CHNN's chains at N = 1, 3, 5 (lnn-start section)")
    parser.add_argument("--lnn-seeds", dest="lnn_seeds", type=hnn.cli.int_at_least(1), default=5,
                        help="seeds of --lnn-start")
    parser.add_argument("--lnn-steps", dest="lnn_steps", type=hnn.cli.int_at_least(0), default=0,
                        help="training steps of --lnn-start after the first batch (0: none)")
    parser.add_argument("--report", type=Path, default=None,
                        help="measure nothing: rewrite the tables (and with --update-docs the section) from a "
                             "stress.json or lnn-start.json this command wrote, stamped with its own command and commit")
    args = parser.parse_args(argv)
    if args.report is not None:
        return _report(args.report, args.update_docs)
    torch.set_num_threads(1)
    meta = {**provenance(), "command": commands.portable_command(sys.argv[1:] if argv is None else list(argv),
                                                                 "analysis/stress.py")}
    tic, cpu = time.perf_counter(), _cpu_seconds()
    if args.lnn_start:
        results = {"lnn_start": lnn_start(seeds=args.lnn_seeds, steps=args.lnn_steps, save_dir=args.out / "chain")}
    else:
        results = run(args.quick, args.seed, args.jobs)
    meta["seconds"], meta["cpu_seconds"] = time.perf_counter() - tic, _cpu_seconds() - cpu
    meta["load"] = os.getloadavg()[0]
    meta["jobs"] = 1 if args.lnn_start else args.jobs
    results["meta"] = meta
    if args.lnn_start:
        body = lnn_start_text(results["lnn_start"], meta, args.lnn_steps)
        commands.publish(args.out, "lnn-start", results, body, {"lnn-start": body} if args.update_docs else {})
    else:
        body = text(results, meta)
        commands.publish(args.out, "stress", results, body, {"stress": body} if args.update_docs else {})
    return results


if __name__ == "__main__":
    main()
