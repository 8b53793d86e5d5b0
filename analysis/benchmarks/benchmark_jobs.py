"""The benchmark's jobs (``analysis/benchmarks/benchmark.py`` is its command): what each job times, ours
against the original's way, and ``run_jobs``, which runs the ones asked for.

``floor``: one training step of the spring HNN (750 x 2, 200 hidden, full batch) and of the pixel
HNN (batch 200 of 16000 pairs of 28x28 frames; uniform noise for pixels, which costs dense work the
same) against their matrix-product floor, by ``analysis/benchmarks/floor.py``: every product the step
performs (captured during one step, forward, backward and double backward), each timed alone in
its fastest layout, alternated with the step for ``--floor-rounds`` rounds (the pixel step a
quarter as many), first at 1 thread, then at 2 in the same process (``hnn.threads.torch_threads``).
The step is ``hnn.trainers.loop.optimizer_step``, the very function ``hnn.train`` runs. It checks the pixel
loss and its gradients against the original's formulation on one batch.

``rollout``: a learned field on a few states, a fixed-step step and dopri5 against their floors
and against torchdiffeq and scipy, by ``analysis/benchmarks/benchmark_rollouts.py`` (its docstring says how).

``group``: G spring HNNs trained as one program (``hnn.trainers.closed_form``) against G separate runs, per width
and G, in model-steps per second, and the grouped step against its batched products' floor, by
``analysis/benchmarks/benchmark_group.py`` (its docstring says how). ``--update-docs`` keeps its table
apart in the generated section of docs/speed.md, under its own stamp: a run with ``--jobs group``
rewrites that part alone, a run without it leaves that part as it was.

Three jobs of the spring task (H = q^2 + p^2), each run two ways from the same inputs:

1. ``data``: the 50-trajectory dataset. Ours integrates all trajectories in one batched
   ``solve_ivp`` call. The original called ``solve_ivp`` once per trajectory and then
   evaluated the derivative targets one point at a time in Python.
2. ``train``: 2001 full-batch Adam steps of the HNN (lr 1e-3, weight decay 1e-4) from the
   same initial weights. Ours uses the closed-form input gradient of the tanh MLP, the fused
   Adam kernel and measures the test loss every 200 steps without a graph. The original took
   the input gradient with ``autograd.grad(..., create_graph=True)`` and measured the test
   loss on the full test set at every step, also with ``create_graph=True``, so each step
   built a second double-backward graph that was never used.
3. ``eval``: the energy MSE of one trained HNN over 15 start states (corrected protocol:
   t in [0, 20], 100 points, RK45 rtol 1e-12). Ours integrates the 15 trials in one batched
   call, for the truth and for the model. The original called ``solve_ivp`` once per trial
   for the truth and once per trial for the model, evaluating the model on one state at a
   time (a float32 [1, 2] tensor with requires_grad, autograd with create_graph=True) for
   every one of the thousands of RK45 stages.

The "original" side is a small re-enactment written here (``analysis/benchmarks/original.py``),
not the original code itself; it does the original's work in the original's way on today's
libraries, with the original's network (``torch.tanh``; ours computes large tanh arrays as
2 sigmoid(2a) - 1). Each job runs ours, original, ours, original, ... for ``--repeats`` rounds; the
table gives the median seconds of each and the ratio original / ours. Each job also checks
that the two ways give the same numbers to a stated tolerance; the exit code is 1 if any
check fails. Timings on a shared or busy machine are noisy: rerun on an idle one.
"""
from __future__ import annotations

import dataclasses
import statistics
import time
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.threads import torch_threads
from hnn_analysis.benchmarks import benchmark_group, benchmark_rollouts
from hnn_analysis.benchmarks import floor_job, original
from hnn_analysis.benchmarks.floor_job import HIDDEN, LEARN_RATE, WEIGHT_DECAY
from hnn_analysis.provenance import cpu_snapshot, others_load, provenance

# Max abs difference of the dataset arrays. Both sides integrate at rtol 1e-10 but with solve_ivp's
# default atol 1e-6, which dominates for |q|, |p| <= 1: each side is a few 1e-6 off the exact
# solution (recorded in the JSON), and batched vs per-trajectory step control makes them differ
# by as much. The noise and the split are identical.
DATA_TOL = 1e-5
TRAIN_REL_TOL = 0.02     # relative difference of the final full-set train losses
EVAL_REL_TOL = 0.01      # relative difference of the energy MSEs


# --------------------------------------------------------------------------- helpers

def _timed(fn):
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


def _interleave(ours, original, repeats: int):
    """Run ours, original, ours, original, ... ``repeats`` times; seconds of each and the last outputs."""
    t_ours, t_orig = [], []
    out_ours = out_orig = None
    for _ in range(repeats):
        dt, out_ours = _timed(ours)
        t_ours.append(dt)
        dt, out_orig = _timed(original)
        t_orig.append(dt)
    return t_ours, t_orig, out_ours, out_orig


def _summary(t_ours, t_orig) -> dict:
    m_ours, m_orig = statistics.median(t_ours), statistics.median(t_orig)
    return {"seconds_ours": t_ours, "seconds_original": t_orig,
            "median_ours": m_ours, "median_original": m_orig, "ratio_original_over_ours": m_orig / m_ours}


# --------------------------------------------------------------------------- job 1: data

def _ours_data(task) -> dict:
    return task.get_dataset(seed=0)


def _exact_error(d: dict, samples: int = 50, points: int = 30) -> float:
    """Max abs error of the clean states behind the targets against the exact spring solution."""
    dx = np.concatenate([d["dxdt"], d["test_dxdt"]]).astype(np.float64).reshape(samples, points, 2)
    clean = np.stack([-dx[..., 1] / 2, dx[..., 0] / 2], axis=-1)      # (q, p) from (2p, -2q)
    t = np.linspace(0, 3, points)
    c, s = np.cos(2 * t), np.sin(2 * t)
    q0, p0 = clean[:, :1, 0], clean[:, :1, 1]
    exact = np.stack([q0 * c + p0 * s, p0 * c - q0 * s], axis=-1)
    return float(np.abs(clean - exact).max())


def job_data(task, repeats: int) -> tuple[dict, dict]:
    t_ours, t_orig, ours, orig = _interleave(lambda: _ours_data(task), original.original_data, repeats)
    diffs = {k: float(np.abs(ours[k].astype(np.float64) - orig[k]).max()) for k in ("x", "dxdt", "test_x", "test_dxdt")}
    shapes_ok = all(ours[k].shape == orig[k].shape for k in diffs)
    check = floor_job.check("dataset arrays, max abs difference", max(diffs.values()) if shapes_ok else np.inf,
                   DATA_TOL, {"per_array": diffs, "exact_solution_error_ours": _exact_error(ours),
                              "exact_solution_error_original": _exact_error(orig)})
    return {**_summary(t_ours, t_orig), "checks": [check]}, ours


# --------------------------------------------------------------------------- job 2: training

def _ours_train(d: dict, steps: int):
    torch.manual_seed(0)
    model = hnn.build_model(2, HIDDEN)
    stats = hnn.train(model, d["x"], d["dxdt"], d["test_x"], d["test_dxdt"], total_steps=steps,
                      learn_rate=LEARN_RATE, weight_decay=WEIGHT_DECAY, progress=False, threads=None)
    return model, stats


def job_train(d: dict, steps: int, repeats: int) -> tuple[dict, hnn.HNN]:
    t_ours, t_orig, (m_ours, _), (m_orig, _) = _interleave(
        lambda: _ours_train(d, steps), lambda: original.original_train(d, steps), repeats)
    loss_ours = hnn.derivative_mse(m_ours, d["x"], d["dxdt"])[0]
    loss_orig = hnn.derivative_mse(m_orig, d["x"], d["dxdt"])[0]
    test_ours = hnn.derivative_mse(m_ours, d["test_x"], d["test_dxdt"])[0]
    test_orig = hnn.derivative_mse(m_orig, d["test_x"], d["test_dxdt"])[0]
    check = floor_job.check("final full-set train loss, relative difference", floor_job.rel_diff(loss_ours, loss_orig),
                   TRAIN_REL_TOL, {"ours": loss_ours, "original": loss_orig,
                                   "test_loss_ours": test_ours, "test_loss_original": test_orig})
    return {**_summary(t_ours, t_orig), "optimizer_steps": steps + 1, "checks": [check]}, m_ours


# --------------------------------------------------------------------------- job 3: energy MSE

def _ours_eval(task, model, protocol) -> float:
    return hnn.evaluate_energy(task, {"hnn": model}, protocol)["hnn"]["mse"]


def job_eval(task, model, protocol, repeats: int) -> dict:
    if protocol.energy != "hamiltonian" or protocol.time_rescale:
        raise ValueError("the original-style evaluation here uses H = q^2 + p^2 and no time rescaling")
    t_ours, t_orig, mse_ours, (mse_orig, calls) = _interleave(
        lambda: _ours_eval(task, model, protocol), lambda: original.original_eval(model, protocol), repeats)
    check = floor_job.check("energy MSE, relative difference", floor_job.rel_diff(mse_ours, mse_orig), EVAL_REL_TOL,
                   {"ours": mse_ours, "original": mse_orig})
    return {**_summary(t_ours, t_orig), "protocol": dataclasses.asdict(protocol),
            "original_model_calls": calls, "checks": [check]}


JOBS = ("floor", "data", "train", "eval", "rollout", "group")
LABELS = {"data": "data: spring dataset (50 trajectories)", "train": "train: spring HNN ({steps} Adam steps)",
          "eval": "eval: energy MSE, one HNN ({trials} trials)"}


def cpu_flags() -> str:
    """The widest x86 vector extension this CPU reports (matrix products run on it), or ``''``."""
    try:
        flags = Path("/proc/cpuinfo").read_text().split()
    except OSError:
        return ""
    return "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else ""


def run_jobs(args) -> dict:
    """Run the jobs ``args.jobs`` asks for (``args``: the command's flags); their results, the floors,
    rollouts and group tables, the environment and the settings, as ``main`` publishes them."""
    steps = 200 if args.quick else 2000
    protocol = hnn.tasks.get_protocol("spring", "corrected")
    if args.quick:
        protocol = dataclasses.replace(protocol, num_trials=5)
    env = {**provenance(), "torch_threads": args.threads, "cpu": cpu_flags()}
    started = cpu_snapshot()
    print(f"torch {env['torch']} ({env['torch_threads']} threads), numpy {env['numpy']}, scipy {env['scipy']}; "
          f"{args.repeats} interleaved round(s) per job{' (quick)' if args.quick else ''}", flush=True)

    task = hnn.load_task("spring")   # loading the task module is not part of the work compared
    results, dataset, model, floors = {}, None, None, None
    if "floor" in args.jobs:
        floors = floor_job.job_floor(task.get_dataset(seed=0), args.floor_rounds)
    with torch_threads(args.threads):      # the count compared, the caller's back after
        if "data" in args.jobs:
            results["data"], dataset = job_data(task, args.repeats)
            print(f"data done: ours {results['data']['median_ours']:.3f} s, original {results['data']['median_original']:.3f} s",
                  flush=True)
        if dataset is None and ({"train", "eval", "rollout"} & set(args.jobs)):
            dataset = task.get_dataset(seed=0)
        if "train" in args.jobs:
            results["train"], model = job_train(dataset, steps, args.repeats)
            print(f"train done: ours {results['train']['median_ours']:.3f} s, "
                  f"original {results['train']['median_original']:.3f} s", flush=True)
        if model is None and ({"eval", "rollout"} & set(args.jobs)):   # trained once, outside the timed region
            model, _ = _ours_train(dataset, steps)
        if "eval" in args.jobs:
            results["eval"] = job_eval(task, model, protocol, args.repeats)
            print(f"eval done: ours {results['eval']['median_ours']:.3f} s, "
                  f"original {results['eval']['median_original']:.3f} s", flush=True)
        rollouts = None
        if "rollout" in args.jobs:
            rollouts = benchmark_rollouts.job_rollout(model, rounds=max(20, args.floor_rounds // 2),
                                                      repeats=max(1, min(args.repeats, 3)))
        group = benchmark_group.job_group(args.quick, repeats=max(1, min(args.repeats, 3))) if "group" in args.jobs else None
    env["others_load"] = others_load(started, cpu_snapshot())
    return {"steps": steps, "protocol": protocol, "env": env, "results": results, "floors": floors,
            "rollouts": rollouts, "group": group}
