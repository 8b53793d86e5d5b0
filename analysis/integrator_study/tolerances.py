"""The adaptive methods' default tolerances, measured: how well the tasks' true systems keep their energy
under ``hnn.rollout``'s defaults, beside scipy's own defaults and a tighter setting, and what a float32
model's rounding makes of tight tolerances.

    python analysis/integrator_study/tolerances.py                  # prints the table, writes JSON
    python analysis/integrator_study/tolerances.py --update-docs    # docs/integrators.md, "Default tolerances"

For every task with true dynamics and a scene-study horizon (``TaskSpec.scene_study["T"]``): 8 start states in
its training distribution (``settings.start_states``), rolled out over ten training lengths (1001 points) by
each adaptive method at each setting; the number is max |H(t) - H(0)| / |H(0)| over starts and times, with
the wall seconds of the batch. Then a float32 HNN of the spring (300 steps of the default training) rolled
out by dop853 at its float32 default and tighter: the field calls it takes (``stats["nfev"]``).
"""
from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.integrators.adaptive import default_tolerances
from hnn.threads import torch_threads
from hnn_analysis import commands
from hnn_analysis.integrator_study import settings
from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import machine, provenance

METHODS = (("solve_ivp", {}), ("solve_ivp", {"scipy_method": "DOP853"}), ("dopri5", {}), ("dop853", {}))
STARTS, LENGTHS, POINTS = 8, 10, 1001


def settings_measured() -> dict:
    """``{label: (rtol, atol)}``: scipy's defaults, rollout's float64 defaults, a tighter one."""
    return {"scipy's default": (1e-3, 1e-6), "rollout's default": default_tolerances(torch.float64),
            "tighter": (1e-9, 1e-9)}


def energy_rows() -> list[dict]:
    rows = []
    for task in hnn.available_tasks():
        cfg, system = hnn.task_spec(task).scene_study or {}, hnn.load_task(task)
        if "T" not in cfg or not hasattr(system, "dynamics") or task == "pixels":
            continue
        x0 = settings.start_states(task, system, STARTS)
        t = np.linspace(0.0, LENGTHS * cfg["T"], POINTS)
        h0 = system.hamiltonian(x0)
        for method, extra in METHODS:
            for label, (rtol, atol) in settings_measured().items():
                row = {"task": task, "method": hnn.get_solver(method).describe(extra), "setting": label, "rtol": rtol,
                       "atol": atol}
                tic = time.perf_counter()
                try:
                    traj = hnn.rollout(system.dynamics, x0, t, method=method, rtol=rtol, atol=atol, **extra)
                except hnn.DivergenceError as err:
                    rows.append({**row, "failed": str(err).split(";")[0][:80], "seconds": time.perf_counter() - tic})
                    continue
                seconds = time.perf_counter() - tic
                h = system.hamiltonian(traj.reshape(-1, traj.shape[-1])).reshape(traj.shape[:2])
                rows.append({**row, "seconds": seconds,
                             "energy_error": float(((h - h0[:, None]).abs() / h0.abs()[:, None]).max())})
    return rows


def float32_rows() -> list[dict]:
    """dop853 on a float32 spring HNN at its float32 default and tighter: field calls and seconds."""
    spring = hnn.load_task("spring")
    data = spring.get_dataset(seed=0)
    torch.manual_seed(0)
    model = hnn.HNN(2, hnn.MLP(2, 200, 2))
    hnn.train(model, data["x"], data["dxdt"], total_steps=300, progress=False)
    x0 = settings.start_states("spring", spring, STARTS).float()
    t = np.linspace(0.0, LENGTHS * hnn.task_spec("spring").scene_study["T"], 301)
    rows = []
    for rtol in (default_tolerances(torch.float32)[0], 1e-6, 1e-7, 1e-8):
        stats = {}
        tic = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")         # the tolerance warning is the point of the row
            hnn.rollout(model, x0, t, method="dop853", rtol=rtol, atol=rtol / 100, stats=stats)
        rows.append({"rtol": rtol, "nfev": stats["nfev"], "seconds": time.perf_counter() - tic})
    return rows


def text(results: dict) -> str:
    meta = results["meta"]
    lines = [generated_by(meta, f"{machine(meta)}, one thread") + ": "
             f"max |H(t) - H(0)| / |H(0)| of the true system over {STARTS} starts and {LENGTHS} training lengths, "
             "and the batch's seconds, by setting (rtol / atol).", ""]
    labels = list(settings_measured())
    lines += ["| task | method | " + " | ".join(f"{label} ({r:g} / {a:g})" for label, (r, a) in settings_measured().items())
              + " |", "| --- | --- |" + " ---: |" * len(labels)]
    by = {}
    for row in results["energy"]:
        by.setdefault((row["task"], row["method"]), {})[row["setting"]] = row
    for (task, method), cells in by.items():
        lines.append(f"| {task} | {method} | " + " | ".join(
            (f"{cells[label]['energy_error']:.1e} ({cells[label]['seconds']:.2f} s)" if "energy_error" in cells[label]
             else "failed") if label in cells else "" for label in labels) + " |")
    lines += ["", "dop853 on a float32 HNN of the spring (300 training steps), 8 starts over ten training lengths: "
              + "; ".join(f"rtol {r['rtol']:.2g}: {r['nfev']} field calls ({r['seconds']:.2f} s)" for r in results["float32"])
              + "."]
    return "\n".join(lines) + "\n"


@torch_threads(1)       # one torch thread, the caller's count back after (tests call main in-process)
def main(argv=None) -> dict:
    p = hnn.cli.Parser(prog="tolerances.py", description=__doc__.split("\n\n")[0])
    commands.add_flags(p, out="folder of tolerances.json", out_default=Path("results/tolerances"),
                       update_docs="write the default-tolerances section of docs/integrators.md")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = p.parse_args(argv)
    meta = {**provenance(), "command": commands.portable_command(argv, "analysis/integrator_study/tolerances.py")}
    results = {"meta": meta, "energy": energy_rows(), "float32": float32_rows()}
    body = text(results)
    commands.publish(args.out, "tolerances", results, body, {"default-tolerances": body} if args.update_docs else {})
    return results


if __name__ == "__main__":
    main()
