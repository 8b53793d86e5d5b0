"""Fitted on a few, run on many: the pair kind fitted on a chain of 8 springs, rolled out on chains of N = 8 ... 4096.

    python analysis/bodies.py --quick                     # N = 8 ... 256, library and sampled fits (about a minute)
    python analysis/bodies.py --update-docs               # N = 8 ... 4096, and Adam; docs/bodies.md's section

The pair kind (``--model pairwise``) is fitted once on the lattice task's data (experiment-lattice: 8 bodies,
the default dataset of ``--seed``) by each of ``--fits``: ``library`` (the radial library, one solve),
``swim`` (sampled radial neurons, one solve) and ``adam`` (an MLP of (r, 1/r) by Adam, ``--adam-steps`` steps of
batch 200). The same model, unchanged, then rolls out chains of each N of ``--sizes`` from ``--starts`` start
states of the task's start law, by leapfrog at step ``--dt`` over ``--horizon``, float64. Beside it, the same
leapfrog on the true forces (``experiment-lattice/data.py``, O(N)), and the reference: DOP853 at rtol 1e-10.

Per N and fit:
- **energy error per body**: max over t of |H(x(t)) - H(x(0))| / N along the model's path, H the true energy
  (mean over the starts); the same for the true-force leapfrog;
- **rollout error**: |x(T) - x_ref(T)| / |x_ref(T)| at the horizon (mean over the starts), both integrators;
- **seconds per step**: the median of ``REPEATS`` timed leapfrog rollouts of ``TIMED_STEPS`` steps of all
  starts at once, divided by the steps, for the model and for the true forces, measured in one process.

Prints a table, writes ``bodies.json`` and ``bodies.md`` under ``--out``, and with ``--update-docs`` the
``bodies`` section of docs/bodies.md. Numbers come from this command, never typed by hand.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.interface import SplitField
from hnn.threads import torch_threads
from hnn_analysis import pages
from hnn_analysis.commands import add_flags, portable_command, publish
from hnn_analysis.provenance import machine, provenance

FULL_SIZES = (8, 64, 512, 4096)
QUICK_SIZES = (8, 32, 128, 256)
FITS = ("library", "swim", "adam")
QUICK_FITS = ("library", "swim")
REPEATS = 5             # timed rollouts per N (the median counts)
TIMED_STEPS = 20        # leapfrog steps of each timed rollout
REFERENCE_RTOL = 1e-10


def _fit(fit: str, data: dict, seed: int, adam_steps: int, hidden: int):
    """``(model, seconds, what)`` of the pair kind fitted on the lattice data by ``fit`` (float64)."""
    config = hnn.tasks.task_config("lattice", {"seed": seed})
    args = {**config.to_dict(), "kind": "pairwise", "fit": fit, "hidden_dim": hidden, "dtype": "float64"}
    torch.manual_seed(seed)
    model = hnn.kinds.model_from_args(args)
    x, dxdt = (torch.tensor(data[k], dtype=torch.float64) for k in ("x", "dxdt"))
    with torch_threads(1):
        if fit == "adam":
            stats = hnn.train(model, x, dxdt, total_steps=adam_steps, batch_size=200, seed=seed, weight_decay=0.0,
                              balance="off", units="off", progress=False)
            return model.eval(), stats["seconds"], f"{adam_steps + 1} Adam steps, final loss {stats['train_loss'][-1]:.2e}"
        stats = hnn.fits.solve(model, x, dxdt, fit=fit, seed=seed, progress=False)
    what = stats["fit"].get("equation") or f"{hidden} sampled radial neurons"
    return model.eval(), stats["seconds"], f"{what}; train loss {stats['train_loss'][0]:.2e}"


def _true_field(data_module) -> SplitField:
    """The lattice's true field, split as a leapfrog reads it (dT/dp = p, dV/dq in O(N))."""
    return SplitField(data_module.dynamics, lambda p: p, data_module.potential_gradient)


def _seconds_per_step(field, x0: torch.Tensor, dt: float) -> float:
    t = np.arange(TIMED_STEPS + 1) * dt
    times = []
    with torch.no_grad():
        hnn.rollout(field, x0, t[:3], method="leapfrog", dt=dt)          # warm-up: first-call setup
        for _ in range(REPEATS):
            tic = time.perf_counter()
            hnn.rollout(field, x0, t, method="leapfrog", dt=dt)
            times.append(time.perf_counter() - tic)
    return statistics.median(times) / TIMED_STEPS


def _errors(path: torch.Tensor, reference: torch.Tensor, energy, count: int) -> dict:
    """Energy error per body (max over t, mean over starts) and the rollout error at the horizon."""
    H = energy(path.reshape(-1, path.shape[-1])).reshape(path.shape[:2])
    per_body = ((H - H[:, :1]).abs().max(dim=1).values / count).mean()
    end, ref = path[:, -1], reference[:, -1]
    rollout = (torch.linalg.vector_norm(end - ref, dim=1) / torch.linalg.vector_norm(ref, dim=1)).mean()
    return {"energy_per_body": float(per_body), "rollout": float(rollout)}


def study(sizes, fits, seed: int, starts: int, dt: float, horizon: float, adam_steps: int, hidden: int) -> dict:
    data_module = hnn.load_task("lattice")
    data = hnn.tasks.task_config("lattice", {"seed": seed}).dataset()
    models = {}
    for fit in fits:
        model, seconds, what = _fit(fit, data, seed, adam_steps, hidden)
        models[fit] = model
        print(f"fitted {fit} on N = {data_module.NUM_BODIES} in {seconds:.2f} s: {what}", flush=True)
        models[fit + ":meta"] = {"seconds": seconds, "what": what}
    truth = _true_field(data_module)
    t = np.linspace(0.0, horizon, int(round(horizon / dt)) + 1)
    rows = []
    with torch_threads(1):
        for count in sizes:
            rng = np.random.RandomState(seed + 1000)
            x0 = torch.tensor(np.stack([data_module.random_config(rng, count) for _ in range(starts)]))
            with torch.no_grad():
                reference = hnn.rollout(data_module.dynamics, x0, t, method="dop853", rtol=REFERENCE_RTOL,
                                        atol=REFERENCE_RTOL)
                true_path = hnn.rollout(truth, x0, t, method="leapfrog", dt=dt)
            row = {"N": count, "true": {**_errors(true_path, reference, data_module.hamiltonian, count),
                                        "seconds_per_step": _seconds_per_step(truth, x0, dt)}}
            for fit in fits:
                with torch.no_grad():
                    path = hnn.rollout(models[fit].field, x0, t, method="leapfrog", dt=dt)
                row[fit] = {**_errors(path, reference, data_module.hamiltonian, count),
                            "seconds_per_step": _seconds_per_step(models[fit].field, x0, dt)}
            rows.append(row)
            print(_row_line(row, fits), flush=True)
    return {"rows": rows, "fits": {fit: models[fit + ":meta"] for fit in fits},
            "settings": {"sizes": list(sizes), "fits": list(fits), "seed": seed, "starts": starts, "dt": dt,
                         "horizon": horizon, "adam_steps": adam_steps, "hidden_dim": hidden,
                         "trained_on": data_module.NUM_BODIES, "method": "leapfrog", "reference_rtol": REFERENCE_RTOL,
                         "repeats": REPEATS, "timed_steps": TIMED_STEPS, "threads": 1}}


def _row_line(row: dict, fits) -> str:
    cells = [f"N={row['N']}", f"true: E/N {row['true']['energy_per_body']:.2e} "
                              f"err {row['true']['rollout']:.2e} {row['true']['seconds_per_step'] * 1e3:.3f} ms"]
    cells += [f"{fit}: E/N {row[fit]['energy_per_body']:.2e} err {row[fit]['rollout']:.2e} "
              f"{row[fit]['seconds_per_step'] * 1e3:.3f} ms" for fit in fits]
    return " | ".join(cells)


def table(results: dict) -> str:
    """The page's section: how each fit was found, then one table per fit against N with the true forces beside."""
    meta, settings = results["meta"], results["settings"]
    lines = [pages.generated_by(meta, f"{machine(meta)}, torch {meta.get('torch', '?')}, one thread") + ".", "",
             f"Fitted on a chain of {settings['trained_on']} bodies (seed {settings['seed']}); each N rolled out from "
             f"{settings['starts']} starts by leapfrog at dt = {settings['dt']:g} to t = {settings['horizon']:g}, "
             f"float64; reference DOP853 at rtol {settings['reference_rtol']:g}.", ""]
    for fit, how in results["fits"].items():
        lines.append(f"- `{fit}` ({how['seconds']:.2f} s to fit): {how['what']}")
    for fit in settings["fits"]:
        lines += ["", f"**{fit}**", "",
                  "| N | energy error / body | true forces' | rollout error | true forces' | ms / step | true forces' "
                  "| ratio |", "|---|---|---|---|---|---|---|---|"]
        for row in results["rows"]:
            mine, true = row[fit], row["true"]
            lines.append(f"| {row['N']} | {mine['energy_per_body']:.2e} | {true['energy_per_body']:.2e} | "
                         f"{mine['rollout']:.2e} | {true['rollout']:.2e} | {mine['seconds_per_step'] * 1e3:.3f} | "
                         f"{true['seconds_per_step'] * 1e3:.3f} | "
                         f"{mine['seconds_per_step'] / true['seconds_per_step']:.1f}x |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    add_flags(p, quick=f"N = {', '.join(map(str, QUICK_SIZES))} and the least-squares fits only (no Adam)",
              out="folder for bodies.json and bodies.md", out_default=Path("results/bodies"),
              update_docs="write the bodies section of docs/bodies.md")
    p.add_argument("--sizes", type=int, nargs="+", help=f"chain lengths N (default {FULL_SIZES}; --quick {QUICK_SIZES})")
    p.add_argument("--fits", nargs="+", choices=FITS, help=f"how the pair kind is fitted (default {FITS}; --quick "
                                                          f"{QUICK_FITS})")
    p.add_argument("--seed", type=int, default=0, help="the training data's seed and the fits' (default 0)")
    p.add_argument("--starts", type=int, default=4, help="start states per N (default 4)")
    p.add_argument("--dt", type=float, default=0.05, help="the leapfrog's step (default 0.05)")
    p.add_argument("--horizon", type=float, default=10.0, help="the rollouts' length in time units (default 10)")
    p.add_argument("--adam-steps", dest="adam_steps", type=int, default=2000, help="Adam's steps (default 2000)")
    p.add_argument("--hidden-dim", dest="hidden_dim", type=int, default=64,
                   help="the MLP's width (adam) and the sampled neurons (swim) (default 64)")
    args = p.parse_args(argv)
    sizes = tuple(args.sizes or (QUICK_SIZES if args.quick else FULL_SIZES))
    fits = tuple(args.fits or (QUICK_FITS if args.quick else FITS))
    for value, name in ((args.starts, "--starts"), (args.dt, "--dt"), (args.horizon, "--horizon")):
        if not value > 0:
            raise SystemExit(f"{name} {value}: must be > 0")
    if min(sizes) < 2:
        raise SystemExit(f"--sizes {min(sizes)}: a chain needs at least 2 bodies")
    results = study(sizes, fits, args.seed, args.starts, args.dt, args.horizon, args.adam_steps, args.hidden_dim)
    results["meta"] = {**provenance(), "command": portable_command(list(sys.argv[1:] if argv is None else argv),
                                                                    "analysis/bodies.py")}
    text = table(results)
    publish(args.out, "bodies", results, text, {"bodies": text} if args.update_docs else None)
    return results


if __name__ == "__main__":
    main()
