"""The speed / accuracy study's measurements (``analysis/integrator_study/speed_accuracy.py`` is its
command): every method x setting x dtype of ``hnn.rollout`` timed and scored against a float64 DOP853
rtol 1e-12 reference of the same field, on the true systems and the trained models, then the extremes.
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn_analysis.integrator_study import peer_solvers
from hnn_analysis.integrator_study.settings import solver_settings, start_states, timed_rollout

DTYPES = {"float32": torch.float32, "float64": torch.float64}
RTOLS = (1e-3, 1e-6, 1e-9, 1e-12)
QUICK_RTOLS = (1e-3, 1e-9)
# the peers' adaptive solvers measured beside ours at the same tolerances (scipy's RK45 and DOP853 are
# already in the grid, as hnn.rollout's solve_ivp); left out where torchdiffeq is not installed
STUDY_PEERS = ("torchdiffeq dopri5", "torchdiffeq dopri8")
# per task: the horizon, the fixed steps (two decades), how many start states


def study_settings(task: str) -> dict | None:
    """``task``'s settings (``TaskSpec.integrator_study``: T, dts, batch, model_time, quick), or None for a
    task without true dynamics to measure against."""
    found = hnn.task_spec(task).integrator_study
    return None if found is None else dict(found)


# a model's field costs ~0.1-0.3 ms a call (vs ~0.02 ms for a true one) and the error of a learned
# model's rollout is measured against its own field: the coarse decade of steps shows the trade
MODEL_DTS = 3
QUICK_DT_PICK = (0, 2, 4)          # first, middle and last step size


def _settings(kind: str, quick: bool, dts, separable: bool = False, energy: bool = False) -> list[tuple[str, dict]]:
    """(method label, rollout options) of the grid; ``kind`` is 'true' (separable H) or 'model'
    (a learned field, ``separable`` for a model kind with a separable H, ``energy`` for a field that
    carries its H)."""
    dts = list(dts) if kind == "true" else list(dts[:MODEL_DTS])
    picked = [dts[i] for i in QUICK_DT_PICK if i < len(dts)] if quick else dts
    return solver_settings(kind == "true" or separable, QUICK_RTOLS if quick else RTOLS, picked, energy=energy)


def _fields(task: str, system, runs: Path | None, notes: list) -> dict:
    """{label: (field per dtype, energy function, kind)} for the true system and each saved model."""
    # the exactly conserved H where the task's own energy is a fit (pixels: 1.9 vs 1.875)
    true_h = getattr(system, "true_hamiltonian", system.hamiltonian)
    fields = {"true": ({name: system.dynamics for name in DTYPES}, true_h, "true", None)}
    if runs is None:
        return fields
    # every model kind the task trains (hnn.MODEL_KINDS): those reproduce.py --models trained are measured
    for label in hnn.cli.model_choices(hnn.load_task(task, "train").Config):
        if hnn.MODEL_KINDS[label].steps:        # no field for these solvers: docs/maps.md sets maps beside them
            continue
        args = hnn.tasks.task_config(task, {"save_dir": str(runs), "seed": 0, "model": label})
        found = hnn.runs.find_run(args)
        if found is None and label not in ("hnn", "baseline"):
            continue
        if found is None:
            notes.append(f"{task} {label}: no saved run at {hnn.runs.run_dir(args)} (train it with analysis/reproduce.py); skipped")
            print(f"  {task} {label}: not found at {hnn.runs.run_dir(args)}, skipped", flush=True)
            continue
        model, saved_args, _ = hnn.load_run(found)
        per_dtype = {name: copy.deepcopy(model).to(dtype).field for name, dtype in DTYPES.items()}
        model64 = copy.deepcopy(model).double()
        x0 = None
        if isinstance(model, hnn.PixelHNN):
            # a latent model: its start states are the encoded first frames of training trials, and a
            # baseline's latent has no energy to track
            data = hnn.tasks.run_dataset(task, saved_args)       # the frames the run trained on
            rows = np.arange(study_settings(task)["batch"]) * (data["params"]["timesteps"] - 3)
            with torch.no_grad():
                x0 = model64.encode(torch.as_tensor(data["pixels"][rows], dtype=torch.float64))
            energy = None if label == "baseline" else model64.hamiltonian
        else:
            energy = system.hamiltonian if label == "baseline" else model64.hamiltonian
        fields[label] = (per_dtype, energy, "model", x0)
    return fields


def _energy_drift(energy, traj: torch.Tensor) -> float | None:
    if energy is None:          # a latent without a Hamiltonian (the pixel baseline)
        return None
    batch, steps, dim = traj.shape
    with torch.no_grad():
        H = energy(traj.double().reshape(-1, dim)).reshape(batch, steps)
    return hnn.metrics.energy_drift(H)


def measure_task(task: str, runs: Path | None, quick: bool, repeats: int, notes: list) -> list[dict]:
    system = hnn.load_task(task)
    cfg = study_settings(task)
    true_x0 = start_states(task, system, cfg["batch"])
    rows = []
    for label, (per_dtype, energy, kind, x0) in _fields(task, system, runs, notes).items():
        scale = cfg.get("model_time", 1.0) if kind == "model" else 1.0
        x0 = true_x0 if x0 is None else x0
        t = np.linspace(0, cfg["T"] * scale, 51)
        with torch.no_grad():
            ref = hnn.rollout(per_dtype["float64"], x0, t, scipy_method="DOP853", rtol=1e-12, atol=1e-12)
        separable = kind == "model" and hnn.MODEL_KINDS[label].separable
        carries_h = hnn.interface.carries_energy(per_dtype["float64"])
        grid = [(method, options, hnn.rollout)
                for method, options in _settings(kind, quick, tuple(dt * scale for dt in cfg["dts"]), separable, carries_h)]
        grid += [(peer.name, {"rtol": rtol, "atol": rtol}, peer.run) for rtol in (QUICK_RTOLS if quick else RTOLS)
                 for peer in peer_solvers.available(STUDY_PEERS)]
        for method, options, runner in grid:
            for dname, dtype in DTYPES.items():
                rtol = options.get("rtol")
                if rtol is not None and rtol < 100 * torch.finfo(dtype).eps:
                    continue                        # below what the dtype can honour: it only warns
                setting = f"rtol={rtol:g}" if rtol is not None else f"dt={options['dt']:g}"
                row = {"task": task, "model": label, "method": method, "setting": setting, "dtype": dname}
                try:
                    sec, traj, stats = timed_rollout(per_dtype[dname], x0.to(dtype), t, options, repeats, runner=runner)
                except hnn.DivergenceError as err:
                    row.update(status=type(err).__name__, message=str(err).split(".")[0])
                    rows.append(row)
                    continue
                row.update(status="ok", seconds=sec, nfev=stats.get("nfev"),
                           error=float((traj.double() - ref).abs().max()), energy_drift=_energy_drift(energy, traj))
                rows.append(row)
        print(f"  {task} {label}: {sum(r['model'] == label for r in rows)} settings", flush=True)
    return rows


# ------------------------------------------------------------------------- the extremes

def extremes(quick: bool, runs: Path | None, notes: list) -> list[dict]:
    """Long horizons, the separatrix, stability limits, and models far from their data."""
    out = []
    spring, pend = hnn.load_task("spring"), hnn.load_task("pend")

    def run(case, f, energy, x0, t, exact=None, **options):
        row = {"case": case, "method": options["method"], "setting": f"dt={options.get('dt')}"}
        try:
            sec, traj, stats = timed_rollout(f, x0, t, options, 1)
        except hnn.DivergenceError as err:
            row.update(status=type(err).__name__, message=str(err).split(". ")[0])
            out.append(row)
            return
        H0 = energy(x0)
        row.update(status="ok", seconds=sec, nfev=stats["nfev"],
                   rel_energy_error=_energy_drift(energy, traj) / float(H0.abs().min()))
        if exact is not None:
            row["error"] = float((traj - exact).abs().max())
        out.append(row)

    # 1. the spring over 10^3 periods (30 in --quick), dt = 0.1: against the analytic rotation
    periods = 30 if quick else 1000
    x0 = torch.tensor([[1.0, 0.0], [0.0, 0.5]], dtype=torch.float64)
    t = np.linspace(0, periods * math.pi, 201)
    c, s = np.cos(2 * t), np.sin(2 * t)
    exact = torch.tensor(np.stack([x0[:, :1].numpy() * c + x0[:, 1:].numpy() * s,
                                   x0[:, 1:].numpy() * c - x0[:, :1].numpy() * s], -1))
    for method in ("leapfrog", "midpoint", "yoshida4", "rk4"):
        run(f"spring, {periods} periods", spring.dynamics, spring.hamiltonian, x0, t, exact, method=method, dt=0.1)
    # 2. the pendulum just inside its separatrix (H = 6) and rotating over the top
    t = np.linspace(0, 20, 201)
    for label, p0 in (("pend, separatrix (H = 6 (1 - 2e-4))", math.sqrt(6) * (1 - 1e-4)), ("pend, over the top (H = 9)", 3.0)):
        x0 = torch.tensor([[0.0, p0]], dtype=torch.float64)
        ref = hnn.rollout(pend.dynamics, x0, t, scipy_method="DOP853", rtol=1e-12, atol=1e-12)
        for method in ("leapfrog", "midpoint", "yoshida4", "rk4"):
            run(label, pend.dynamics, pend.hamiltonian, x0, t, ref, method=method, dt=0.05)
    # 3. step sizes at and past each method's stability limit on the spring (omega = 2)
    x0 = torch.tensor([[1.0, 0.0], [0.5, 0.5]], dtype=torch.float64)
    for method, dts in (("leapfrog", (0.95, 1.05)), ("yoshida4", (0.75, 0.85)), ("rk4", (1.38, 1.45)),
                        ("midpoint", (0.9, 1.1))):
        for dt in dts:
            run("spring, stability limit", spring.dynamics, spring.hamiltonian, x0,
                np.linspace(0, 1000 * dt, 101), method=method, dt=dt)
    # 4. learned models far outside their training radii (spring data: radius 0.1 .. 1)
    if runs is not None:
        for label in ("hnn", "baseline"):
            args = hnn.tasks.task_config("spring", {"save_dir": str(runs), "seed": 0, "model": label})
            found = hnn.runs.find_run(args)
            if found is None:
                notes.append(f"extremes: spring {label} not found; its out-of-distribution rows are skipped")
                continue
            model = hnn.load_run(found)[0].double()
            for radius in (0.5, 2.0, 8.0, 100.0):
                x0 = torch.tensor([[radius, 0.0]], dtype=torch.float64)
                t = np.linspace(0, 5, 51)
                exact = torch.tensor([[[radius * np.cos(2 * s), -radius * np.sin(2 * s)] for s in t]])
                method = "midpoint" if label == "hnn" else "rk4"
                run(f"spring {label}, radius {radius:g} (trained on 0.1 .. 1)", model.field,
                    spring.hamiltonian, x0, t, exact, method=method, dt=0.02)
                out[-1]["error_relative"] = out[-1].get("error", float("nan")) / radius
    return out


# ------------------------------------------------------------------------- output
