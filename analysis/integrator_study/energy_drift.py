"""Long-horizon drift of the learned H: the energy-preserving integrator beside the symplectic ones.

    python analysis/integrator_study/energy_drift.py                     # 10^4 steps of dt = 0.1 (docs/integrators.md)
    python analysis/integrator_study/energy_drift.py --steps 2000 --update-docs

A spring HNN and a separable HNN are trained (``experiment-spring/train.py``'s config, ``--train-steps``
steps; a saved run of the same config is reused), then each is rolled out in float64 from 8 start
states for ``--steps`` steps of ``--dt`` by every integrator that serves it: RK4 (neither symplectic
nor energy-preserving), the implicit midpoint (symplectic: the learned H oscillates within a bound),
leapfrog (symplectic, explicit; the separable model only) and the discrete gradient (keeps the
learned H to its solve's tolerance, 1e-12 relative in float64). Reported per pair: the largest
|H(x_t) - H(x_0)| / |H(x_0)| of the model's own H over all steps and starts, its value at the last
step, the field calls a step and the seconds a step (one torch thread; the wall time of the whole
rollout over the steps). Writes ``energy_drift.json`` under ``--out``; ``--update-docs`` puts the
table into docs/integrators.md.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.sweeps import sweep
from hnn.threads import torch_threads
from hnn_analysis import commands, plan
from hnn_analysis.commands import portable_command
from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import machine, provenance

# model kind -> the integrators compared on it
METHODS = {"hnn": ("rk4", "midpoint", "discrete_gradient"),
           "separable": ("rk4", "leapfrog", "midpoint", "discrete_gradient")}
STARTS = 8


def trained(kind: str, steps: int, out: Path):
    """A spring model of ``kind`` trained ``steps`` steps (reused when saved), in float64."""
    config = hnn.tasks.task_config("spring", {"model": kind, "total_steps": steps, "save_dir": str(out / "runs")})
    run = hnn.runs.find_run(config) or hnn.run_experiment(config)
    return hnn.evaluation.float64_copy(hnn.load_run(run)[0])


def drift(model, method: str, steps: int, dt: float) -> dict:
    """The learned H's relative drift along ``model``'s rollout by ``method``, its cost a step."""
    rng = np.random.RandomState(0)
    x0 = rng.uniform(0.2, 1.0, (STARTS, 2)) * rng.choice([-1.0, 1.0], (STARTS, 2))
    x0 = torch.as_tensor(x0, dtype=torch.float64)
    t = dt * np.arange(steps + 1)
    stats = {}
    tic = time.perf_counter()
    path = hnn.rollout(model, x0, t, method=method, dt=dt, stats=stats)
    seconds = time.perf_counter() - tic
    with torch.no_grad():
        h = model.hamiltonian(path.reshape(-1, 2)).reshape(STARTS, -1)
    relative = ((h - h[:, :1]).abs() / h[:, :1].abs()).numpy()
    return {"max": float(relative.max()), "last": float(relative[:, -1].max()),
            "field_calls_per_step": stats["nfev"] / steps, "seconds_per_step": seconds / steps}


def table(results: dict) -> str:
    """The markdown of ``results`` (``energy_drift.json``): its stamp, one row per (model, integrator)."""
    meta = results["meta"]
    lines = [generated_by(meta, f"{machine(meta)}, one torch thread") + ": "
             f"{results['steps']} steps of dt = {results['dt']:g} from {STARTS} starts, spring models trained "
             f"{results['train_steps']} steps, float64. Drift: |H(x_t) - H(x_0)| / |H(x_0)| of the model's own H, the "
             "largest over the starts.", "",
             "| model | integrator | largest drift | drift at the last step | field calls a step | ms a step |",
             "| --- | --- | ---: | ---: | ---: | ---: |"]
    for kind, rows in results["rows"].items():
        for method, r in rows.items():
            lines.append(f"| {kind} | {method} | {r['max']:.2e} | {r['last']:.2e} | {r['field_calls_per_step']:.2f} | "
                         f"{1e3 * r['seconds_per_step']:.3f} |")
    return "\n".join(lines) + "\n"


@torch_threads(1)       # one torch thread, the caller's count back after (tests call main in-process)
def main(argv=None) -> dict:
    parser = hnn.cli.Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=10_000, help="integrator steps of each rollout")
    parser.add_argument("--dt", type=float, default=0.1, help="step size (the spring's period is 2 pi)")
    parser.add_argument("--train-steps", dest="train_steps", type=int, default=2000, help="training steps of each model")
    commands.add_flags(parser, out="folder for runs and json", out_default=Path("results/energy_drift"),
                       update_docs="write the table into docs/integrators.md")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.train_steps < 1 or not (args.dt > 0 and np.isfinite(args.dt)):
        sys.exit(f"error: --steps and --train-steps must be positive and --dt positive and finite, got "
                 f"{args.steps}, {args.train_steps}, {args.dt}")
    argv = sys.argv[1:] if argv is None else list(argv)
    meta = {**provenance(), "command": portable_command(argv, "analysis/integrator_study/energy_drift.py")}
    rows, progress = {}, sweep.Progress(sum(len(methods) for methods in METHODS.values()))
    plan.say("energy_drift", [plan.Stage("train", len(METHODS), f"models of {args.train_steps} steps (a saved one is reused)"),
                              plan.Stage("roll out", progress.total, f"drift runs of {args.steps} steps")])
    for kind, methods in METHODS.items():
        model = trained(kind, args.train_steps, args.out)
        rows[kind] = {}
        for method in methods:
            rows[kind][method] = drift(model, method, args.steps, args.dt)
            print(f"{progress.advance()} {kind} {method}: largest drift {rows[kind][method]['max']:.2e}", flush=True)
    results = {"meta": meta, "steps": args.steps, "dt": args.dt, "train_steps": args.train_steps, "rows": rows}
    text = table(results)
    commands.publish(args.out, "energy_drift", results, text, {"energy-drift": text} if args.update_docs else {})
    return results


if __name__ == "__main__":
    main()
