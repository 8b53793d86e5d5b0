"""The two-link arm: the paper's HNN against the mechanical kind at one training budget.

    python analysis/arm.py --steps 3000 --seeds 0 1 2 [--mass 1] [--models hnn mechanical] [--balance off auto] [--units off] [--out DIR] [--update-docs]

Trains each model at each seed through ``experiment-arm/train.py``'s config (one run at a time,
reusing complete saved runs), then measures on held-out data of the same seed:

- **field error**: |f_model(x) - f_true(x)| / |f_true(x)| over the 1000 test states (Frobenius);
- **rollout error**: e(t) = |x^(t) - x(t)| / (|x^(t)| + |x(t)|) over 16 held-out starts and 3 s,
  geometric mean over t, mean over starts (``hnn.metrics.summarize_errors``); the model is rolled
  out with dopri5 at rtol 1e-7 in float64, the truth at 1e-10;
- for the mechanical kind, the error of its learned M^-1(q) against the arm's at the test states.

Prints a table and writes ``arm.json`` (every number, the runs' folders and training seconds)
under ``--out``. Numbers come from the saved runs, never typed by hand (docs/scenes.md).
"""
from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path

import torch

import hnn
from hnn.sweeps import sweep
from hnn.io import write_json
from hnn.threads import torch_threads
from hnn_analysis import pages
from hnn_analysis.commands import portable_command
from hnn_analysis.provenance import machine, provenance

RTOL = 1e-7


def measure(folder: Path, arm) -> dict:
    """The field, rollout (and M^-1) errors of the saved run in ``folder`` on the arm ``arm``."""
    data = hnn.load_task("arm")
    model, args, metrics = hnn.load_run(folder)
    model = model.double()
    ds = hnn.tasks.task_config("arm", args).dataset()
    x, dxdt = (torch.tensor(ds[k], dtype=torch.float64) for k in ("test_x", "test_dxdt"))
    with torch.no_grad():
        pred = model.time_derivative(x)
    out = {"field_error": float((pred - dxdt).norm() / dxdt.norm()),
           "train_seconds": metrics["train_seconds"], "test_loss": metrics["test_loss"], "run": str(folder)}
    x0, t = torch.tensor(ds["rollout_x0"]), ds["t_eval"]
    paths = hnn.rollout(model.time_derivative, x0, t, method="dopri5", rtol=RTOL, atol=RTOL)
    out["rollout_error"] = hnn.metrics.summarize_errors(
        hnn.metrics.relative_error(paths, data.trajectories(arm, x0, t)), t)["error"]
    if isinstance(getattr(model, "inner", model), hnn.MechanicalHNN):      # the kind that learns M^-1(q), rescaled or not
        with torch.no_grad():
            learned, true = model.inverse_mass(x[:, :2]), torch.linalg.inv(arm.mass_matrix(x[:, :2]))
        out["inverse_mass_error"] = float((learned - true).norm() / true.norm())
        out["inverse_mass_min_eig_ratio"] = float((torch.linalg.eigvalsh(learned)[:, 0]
                                                   / torch.linalg.eigvalsh(true)[:, 0]).min())
    return out


def _summary(rows: list[dict], key: str) -> str:
    values = [row[key] for row in rows if key in row]
    if not values:
        return "-"
    spread = f" ({min(values):.2e}-{max(values):.2e})" if len(values) > 1 else ""
    return f"{statistics.median(values):.2e}{spread}"


@torch_threads(1)       # one torch thread, the caller's count back after (tests call main in-process)
def main(argv=None) -> dict:
    parser = hnn.cli.Parser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=hnn.settings.int_at_least(1), default=3000, help="optimizer steps per run")
    parser.add_argument("--seeds", type=hnn.settings.int_at_least(0), nargs="+", default=[0, 1, 2])
    parser.add_argument("--models", nargs="+", default=["hnn", "mechanical"], help="model kinds to train")
    parser.add_argument("--mass", type=hnn.settings.positive_float, default=1.0, help="mass of each link in kg")
    parser.add_argument("--balance", choices=hnn.names.BALANCES, nargs="+", default=["auto"],
                        help="the runs' --balance, one set of runs each: the loss's weights of the components of "
                             "dx/dt (hnn.balance)")
    parser.add_argument("--units", choices=hnn.names.UNITS, default="auto",
                        help="the runs' --units (hnn.units): auto, the default, rescales the arm from about 10 kg links "
                             "(p of RMS 24 at 10 kg); off trains in its own units, as the Balanced loss sections do")
    parser.add_argument("--out", default="results/arm", help="folder for the runs and arm.json")
    parser.add_argument("--update-docs", dest="update_docs", action="store_true",
                        help="write the table into its section of docs/stress.md (--section)")
    parser.add_argument("--section", choices=("arm-balance", "arm-balance-long"), default="arm-balance",
                        help="the section of docs/stress.md that --update-docs writes")
    args = parser.parse_args(argv)
    meta = {**provenance(), "command": portable_command(sys.argv[1:] if argv is None else list(argv), "analysis/arm.py")}
    data = hnn.load_task("arm")
    arm = data.Arm((args.mass, args.mass))
    out = Path(args.out)
    results, progress = {}, sweep.Progress(len(args.balance) * len(args.models) * len(args.seeds))
    print(f"{progress.tag()} training and measuring {progress.total} runs", flush=True)
    for balance in args.balance:
        for model in args.models:
            rows = []
            for seed in args.seeds:
                config = hnn.tasks.task_config("arm", {"model": model, "seed": seed, "total_steps": args.steps,
                                                       "mass": args.mass, "balance": balance, "units": args.units,
                                                       "save_dir": str(out / "runs")})
                folder = hnn.runs.find_run(config) or hnn.run_experiment(config)
                rows.append({"seed": seed, **measure(folder, arm)})
                print(f"{progress.advance()} {model} ({balance}) seed {seed}: " + ", ".join(f"{k} {v:.3e}" for k, v in rows[-1].items()
                                                                       if isinstance(v, float)), flush=True)
            results[f"{model} ({balance})"] = rows
    lines = [pages.generated_by(meta, f"{machine(meta)}, one torch thread a run") + ": "
             f"{args.steps} steps a run, links of {args.mass} kg, --units {args.units}, median (min-max) over seeds "
             f"{', '.join(map(str, args.seeds))}; train s is each run's own loop, on a shared box.", "",
             "| model (--balance) | field error | rollout error | M^-1 error | smallest eigenvalue / truth's | train s |",
             "| --- | --- | --- | --- | --- | --- |"]
    for name, rows in results.items():
        lines.append(f"| {name} | {_summary(rows, 'field_error')} | {_summary(rows, 'rollout_error')} | "
                     f"{_summary(rows, 'inverse_mass_error')} | {_summary(rows, 'inverse_mass_min_eig_ratio')} | "
                     f"{statistics.median(r['train_seconds'] for r in rows):.0f} |")
    body = "\n".join(lines) + "\n"
    print("\n" + body)
    report = {"meta": meta, "steps": args.steps, "seeds": args.seeds, "mass": args.mass, "balance": args.balance,
              "units": args.units,
              "rollout_rtol": RTOL, "results": results}
    write_json(out / "arm.json", json.loads(json.dumps(report)))
    if args.update_docs:
        n = len(args.seeds)
        seeds = pages.Seeds(n, None if n >= pages.MIN_SEEDS else f"this run had --seeds {' '.join(map(str, args.seeds))}")
        print(f"updated the {args.section} section of {pages.update_section(args.section, body, seeds)}")
    return report


if __name__ == "__main__":
    main()
