"""The LNN's start on CHNN's chains (``analysis/stress.py --lnn-start``): whether its d2L/dqdot2 can be
solved at the training states and its first batch's loss computed, from each init."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.sweeps import sweep
from hnn_analysis import pages
from hnn_analysis.provenance import machine


def lnn_start(bobs=(1, 3, 5), seeds: int = 5, inits=("lnn", "lnn_convex"), steps: int = 0,
              save_dir: Path = Path("results/stress/chain")) -> list[dict]:
    """The LNN on CHNN's chains as the peers' table trains it (softplus, 256 units, rate 1e-3) from each
    init: per seed the training states (of 40 paths) whose d2L/dqdot2 cannot be solved, the largest
    acceleration at them, whether the first batch's loss (200 RK4 snippets) is computed and, with
    ``steps``, whether that many training steps run."""
    from hnn.models.lagrangian import SingularLagrangianError
    out, progress = [], sweep.Progress(len(bobs) * len(inits) * seeds)
    print(f"{progress.tag()} {progress.total} fresh LNNs to start", flush=True)
    for n in bobs:
        for init in inits:
            for seed in range(seeds):
                config = hnn.tasks.task_config("chain", {"bobs": n, "model": "lagrangian", "nonlinearity": "softplus",
                                                         "learn_rate": 1e-3, "init": init, "n_train": 40, "n_test": 10,
                                                         "seed": seed, "save_dir": str(save_dir)})
                prep = hnn.prepare(config)      # the run's model (drawn from its seed), rows and options
                model, objective, data, options = prep.canonical_model, prep.objective, prep.dataset, prep.options
                z = torch.as_tensor(data["x"][:2000], dtype=torch.float32)
                row = {"bobs": n, "init": init, "seed": seed, "states": len(z)}
                try:
                    with torch.no_grad():
                        row["max_acceleration"] = float(model.acceleration(z).abs().max())
                    row["singular"] = 0
                except SingularLagrangianError as err:
                    row["singular"] = len(err.states)
                first = torch.as_tensor(data[objective.arrays[0]][:200], dtype=torch.float32)
                try:
                    with torch.no_grad():
                        row["first_loss"] = float(options.loss_of(model)(first, first).mean())
                except hnn.DivergenceError as err:
                    row["first_stop"] = f"{type(err).__name__}: {str(err)[:120]}"
                if steps:
                    try:
                        stats = hnn.train(model, prep.x, prep.y, **prep.train_kwargs(total_steps=steps, progress=False,
                                                                                      print_every=10 ** 9))
                        row["trained_loss"] = stats["train_loss"][-1]
                    except hnn.DivergenceError as err:
                        row["train_stop"] = f"{type(err).__name__}: {str(err)[:120]}"
                out.append(row)
                print(progress.advance(), row, flush=True)
    return out


def lnn_start_text(rows: list[dict], meta: dict, steps: int) -> str:
    jobs = f"{meta['jobs']} processes of one torch thread" if meta.get("jobs", 1) > 1 else "one torch thread"
    lines = [pages.generated_by(meta, f"{machine(meta)}, {jobs}") + ", "
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


def start_results_text(results: dict) -> str:
    """``lnn_start_text`` of saved results (their steps: recorded, or read from their command)."""
    command = results["meta"]["command"]
    steps = results.get("steps", int(command.split("--lnn-steps")[1].split()[0]) if "--lnn-steps" in command else 0)
    return lnn_start_text(results["lnn_start"], results["meta"], steps)


def start_seeds(results: dict) -> pages.Seeds:
    n = len({row["seed"] for row in results["lnn_start"]})
    return pages.Seeds(n, None if n >= pages.MIN_SEEDS else f"this run had --lnn-seeds {n}")
