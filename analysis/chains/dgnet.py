"""DGNet's protocol (Matsubara, Ishikawa & Yaguchi, NeurIPS 2020) on the spring, their published
numbers beside ours.

    python analysis/chains/dgnet.py --steps 300 --seeds 2 --out results-dgnet    # a small budget
    python analysis/chains/dgnet.py                                               # their 2000 steps, 15 seeds

The protocol, read from their code (tksmatsubara/discrete-autograd, experiment-spring/train_dgnet.py):
the original HNN spring data with t_span [0, 20] and 5 points per time unit (50 trajectories of
100 states, dt = 20/99, noise std 0.1 on the states, the first 25 for training); the HNN's MLP (two
hidden layers of 200 tanh units, orthogonal init); full-batch Adam, lr 1e-3, weight decay 1e-4,
2000 steps, float32; DGNet fits (x_{n+1} - x_n) / dt of every consecutive pair by the discrete
gradient of H between the two states. Reported: "derivative", the MSE of the learned dx/dt against
the true dx/dt at the test states; "energy", over 15 starts with each of q, p uniform in
+-[0.2, 1.0], the mean over the 100 times of [0, 20] of (E_true - E_model)^2 with E = q^2 + p^2, the
model rolled out one step per interval by the discrete-gradient method (solved to 1e-12), or by
adaptive Dormand-Prince (torchdiffeq's defaults, rtol 1e-7, atol 1e-9). Each published number is
an average over 15 trials (seeds).

Ours: the same data recipe through ``hnn.datasets.ring_dataset``, ``hnn``'s HNN trained with
``--objective discrete_gradient`` (its closed-form discrete gradient is DGNet's chain rule); rolled
out in float64 (theirs: float32 through scipy's fsolve). Our start states draw from their
distribution with our own seeded generator (theirs continue numpy's global stream). Also our HNN on
the paper's objective (true dx/dt at the noisy states): not a row of theirs, which trained the HNN
on the same finite differences through one Dormand-Prince step. Every run saves its config,
metrics and checkpoint (``--out``/runs); the table is written from ``dgnet.json``.
"""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.io import atomic_write, write_json

# their README's table ("Results on the conservative ODE datasets"), spring: (derivative, energy)
PUBLISHED = {
    "NODE (ada. DP / ada. DP)": (5.57e-2, 5.74e-1),
    "HNN (ada. DP / ada. DP)": (3.99e-2, 1.74e-3),
    "SRNN (leapfrog / leapfrog)": (3.95e-2, 6.90e-4),
    "DGNet (discrete gradient / ada. DP)": (3.85e-2, 6.16e-4),
    "DGNet (discrete gradient / discrete gradient)": (3.85e-2, 6.17e-4),
}
T_SPAN, TIMESCALE, TRIALS = (0.0, 20.0), 5, 15
PREDICT = {"discrete gradient": {"method": "discrete_gradient"},
           "ada. DP": {"method": "dopri5", "rtol": 1e-7, "atol": 1e-9}}
# our rows: label -> (objective, the integrators it is predicted with)
OURS = {"DGNet": ("discrete_gradient", ("discrete gradient", "ada. DP")),
        "HNN, paper's objective (true dx/dt)": ("derivative", ("ada. DP",))}


def dataset(seed: int) -> dict:
    """Their spring data: the HNN recipe on [0, 20] at 5 points per time unit."""
    spring = hnn.load_task("spring")
    return hnn.datasets.ring_dataset(spring.dynamics, seed, 50, T_SPAN, TIMESCALE, spring.RADIUS_RANGE,
                                     spring.NOISE_STD)


def energy_mse(model, seed: int, options: dict) -> float:
    """Their energy error: mean over ``TRIALS`` starts and 100 times of (E_true - E_model)^2, E = q^2 + p^2."""
    spring = hnn.load_task("spring")
    rng = np.random.RandomState(10_000 + seed)
    x0 = rng.rand(TRIALS, 2) * 1.6 - 0.8
    x0 += 0.2 * np.sign(x0)
    x0 = torch.as_tensor(x0, dtype=torch.float64)
    t = np.linspace(*T_SPAN, int(TIMESCALE * (T_SPAN[1] - T_SPAN[0])))
    truth = hnn.rollout(spring.dynamics, x0, t, method="dop853", rtol=1e-12, atol=1e-12)
    ours = hnn.rollout(hnn.evaluation.float64_copy(model), x0, t, **options)
    return float((spring.hamiltonian(truth) - spring.hamiltonian(ours)).pow(2).mean())


def measure(objective: str, seed: int, steps: int, out: Path) -> dict:
    """Train one run on their data (saved under ``out``/runs) and measure it on their protocol."""
    trainer = hnn.load_task("spring", "train")
    config = trainer.Config(name="spring-dgnet", objective=objective, total_steps=steps, seed=seed,
                            save_dir=str(out / "runs"))
    data = dataset(seed)
    run = hnn.run_experiment(config, data)
    model = hnn.load_run(run)[0]
    with torch.no_grad():
        pred = model.time_derivative(torch.as_tensor(data["test_x"]))
        derivative = float((pred - torch.as_tensor(data["test_dxdt"])).pow(2).mean())
    return {"run": str(run), "derivative": derivative,
            "energy": {name: energy_mse(model, seed, options) for name, options in PREDICT.items()}}


def table(results: dict) -> str:
    """The markdown table of ``results`` (``dgnet.json``), published rows first."""
    lines = ["| model (train / predict) | derivative | energy | source |", "| --- | --- | --- | --- |"]
    lines += [f"| {name} | {d:.2e} | {e:.2e} | published, mean of 15 |" for name, (d, e) in PUBLISHED.items()]
    n, steps = results["seeds"], results["steps"]
    for label, (objective, predicts) in OURS.items():
        runs = results["rows"][label]
        d = statistics.mean(r["derivative"] for r in runs)
        for predict in predicts:
            energies = [r["energy"][predict] for r in runs]
            spread = f" (min {min(energies):.2e}, max {max(energies):.2e})" if n > 1 else ""
            train = "discrete gradient" if objective == "discrete_gradient" else "dx/dt"
            lines.append(f"| ours: {label} ({train} / {predict}) | {d:.2e} | {statistics.mean(energies):.2e}{spread} "
                         f"| ours, mean of {n} seeds, {steps} steps |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=2000, help="optimizer steps per run (theirs: 2000)")
    parser.add_argument("--seeds", type=int, default=15, help="seeds 0..seeds-1 (theirs: 15 trials)")
    parser.add_argument("--out", type=Path, default=Path("results-dgnet"), help="folder for runs, json, table")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.seeds < 1:
        sys.exit(f"error: --steps and --seeds must be positive, got {args.steps} and {args.seeds}")
    rows = {}
    for label, (objective, _) in OURS.items():
        rows[label] = []
        for seed in range(args.seeds):
            print(f"{label}: seed {seed + 1}/{args.seeds}", flush=True)
            rows[label].append(measure(objective, seed, args.steps, args.out))
    results = {"steps": args.steps, "seeds": args.seeds, "published": PUBLISHED, "rows": rows}
    write_json(args.out / "dgnet.json", results)
    text = table(results)
    atomic_write(args.out / "dgnet.md", lambda tmp: Path(tmp).write_text(text))
    print(text)
    return results


if __name__ == "__main__":
    main()
