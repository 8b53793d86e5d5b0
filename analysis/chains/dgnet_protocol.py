"""DGNet's protocol (Matsubara, Ishikawa & Yaguchi, NeurIPS 2020) as ``analysis/chains/dgnet.py`` runs it:
their published rows, their settings, the data, one run measured, and the tables.

The protocol, read from their code (tksmatsubara/discrete-autograd at e101a09, which overlays the
original HNN repository and reuses its data generators; experiment-{spring,pend,real,2body}/
train_dgnet.py, dgnet/ode.py): spring and pendulum data are the HNN recipe on t in [0, 20] at 5
points per time unit (50 trajectories of 100 states, dt = 20/99, noise std 0.1 on the states, the
first 25 train); the real pendulum is the original's file and split (445 training rows, 110 test
rows, dt = 1/6). One MLP of two hidden layers of 200 tanh units, orthogonal weights and zero biases
(their ``reset_parameters``, every model of theirs: ``--init zero_bias``, our default here); full-batch
Adam at lr 1e-3, 2000 steps (weight decay 1e-4; real 1e-5); float32. Every model fits the finite
differences (x_{n+1} - x_n) / dt of consecutive states: NODE (an MLP field) and HNN through one
adaptive Dormand-Prince solve of the interval, SRNN (H = T(p) + V(q)) through one leapfrog step,
DGNet through the discrete gradient of H between the two states (no solver). Reported:
"derivative", the MSE of the learned dx/dt at the noisy test states against the true dx/dt there
(real: against the test forward differences); "energy", over 15 starts with each of q, p uniform in
+-[0.2, 1.0], the mean over the 100 times of [0, 20] of (E_true - E_model)^2 with E = q^2 + p^2 on
both tasks (their pendulum metric too, not its H); real: one rollout from the first test state over
the 110 test times, against the measured states, E = 2.4 (1 - cos q) + p^2. Rollouts by the
discrete-gradient method, adaptive Dormand-Prince at torchdiffeq's defaults (rtol 1e-7, atol 1e-9)
or leapfrog, one step per interval. Each published number is an average over 15 trials.

Their 2-body (experiment-2body/train_dgnet.py, with the original's experiment-2body/data.py): the
original generator called with timesteps=500 and t_span=[0, 25], its other arguments at their
defaults: 1000 orbits of two unit masses (body 0 at U[0.5, 1.5]^2, the circular-orbit velocity
scaled by 1 + 0.05 N(0, 1) per orbit, body 1 its mirror), each by scipy's RK45 at rtol 1e-9 (atol
1e-6), states x = [qx1, qx2, qy1, qy2, px1, px2, py1, py2] (width 8) with no noise; the first 20% of
the rows (orbits 0-199, 100000 states) test, the rest (800 orbits, 400000 states) train;
dt = 25/499. Pairs: every consecutive pair of each training orbit (399200), the target
(x_{n+1} - x_n) / dt. The same MLPs (8 inputs, 200 tanh units twice; SRNN two such nets on q and
p), Adam at lr 1e-3 without weight decay, 10000 steps (the loop runs 10001) of 200 pairs drawn at
random each step. "derivative": the MSE of the learned dx/dt over all 100000 test states against
the generator's analytic dx/dt. "energy": 15 starts, the original's random_config after
np.random.seed(0..14) (the same at every seed), the true orbit by RK45 (rtol 1e-9) and the model's
over the 500 times of [0, 25], the mean of (E_true - E_model)^2 with E the physical H (kinetic plus
-1/r). Their dataset is cached as experiment-2body/2body-orbits-dataset.pkl, a name without the
seed: unless that file was removed between trials, every trial after the first loaded the first's
orbits.

Ours, and where it differs: the same data recipes (``hnn.datasets.ring_dataset``; experiment-real's
original split; 2-body: ``hnn.orbits.nbody.orbit_dataset`` with experiment-2body's sampler, ``TWO_BODY``:
the original's draws in the original's order, so seed s gives the start states of their
np.random.seed(s), each seed its own, every orbit by a batched Dormand-Prince 5(4) at least as
accurate as their RK45 call, generated in about a second and not cached), their settings per task
(``SETTINGS``), our kinds ``baseline`` (NODE), ``hnn``, ``separable`` (SRNN) and ``hnn`` with
``--objective discrete_gradient`` (DGNet; its closed-form discrete gradient is their chain rule),
each rolled out on the 2-body as on the other tasks. NODE and HNN
train through one RK4 step of the interval, not an adaptive Dormand-Prince solve (our adaptive
solvers are not differentiable; at these intervals RK4's error is far below the data's noise, and
on the noiseless 2-body data the true field's RK4 step misses the pairs' differences by an MSE of
2.7e-12 in derivative units, against 5.3e-6 between those differences and the true dx/dt); NODE,
HNN and SRNN fit the squared state error of that one step, their loss times dt^2, so their weight
decay is scaled by dt^2 too (Adam does not see a loss's scale, but the L2 decay it adds to the
gradient does). Rollouts in float64 (theirs: float32, the discrete gradient through scipy's
fsolve); the 2-body truth by DOP853 at rtol and atol 1e-12. Our ring start states draw from their
law with our own seeded generator; the 2-body ones are theirs exactly. The real pendulum's pairs are
consecutive training rows exactly dt = 1/6 apart: its 445 rows skip frames at 10 places and the
test block at one, and those 11 pairs are left out (theirs fit the forward difference over the true
step there). Their real-pendulum rows most likely trained with their ``--friction`` flag (a learned
friction term; the README lists the task under dissipative data and brackets SRNN, the one model
that cannot use it): the measured energy falls from 0.90 to 0.74 over the test block, so a model
that conserves it scores about 1e-2 there; our D-HNN row (``dissipative``, H and a learned
dissipation) is the model that may lose energy. Their "derivative" there compares a predicted next
state with a derivative (dgnet/ode.py returns the state when no second state is given): ours is the
derivative MSE, not comparable with theirs. Also our HNN on the paper's objective (the true dx/dt at
the data's states: noisy on the spring and pendulum, exact on the 2-body). Every run saves its
config, metrics and checkpoint (``--out``/runs); the table is written from ``dgnet.json``.

The 2-body's cost at their settings, measured here (301-step bursts, one torch thread, on a 2-core
machine whose load average was 4-5 from other jobs): milliseconds per step NODE 8.8, HNN 11.3, SRNN
8.9, DGNet 8.0, HNN on the paper's objective 6.5, so 10001 steps take 65-113 s a row, about 435 s
for the five rows of one seed, plus 7-9 s a run for its data, its final losses over all pairs and
its energy rollouts (one full HNN run: 124 s, 115 s of them training): about 480 s a seed, 24
core-minutes for 3 seeds (15 runs), about 12 minutes on 2 workers. Each task's section in docs/dgnet.md
says what its runs' training cost at their 15 trials (the seconds summed from the runs' saved metrics).
"""
from __future__ import annotations

import statistics
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.objectives.dgnet import pairs_from_paths
from hnn.objectives.trajectory import TrajectoryObjective
from hnn.threads import torch_threads
from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import machine

# their README's tables ("Results on the conservative ODE datasets"): (derivative, energy), means of 15
PUBLISHED = {
    "spring": {"NODE (ada. DP / ada. DP)": (5.57e-2, 5.74e-1), "HNN (ada. DP / ada. DP)": (3.99e-2, 1.74e-3),
               "SRNN (leapfrog / leapfrog)": (3.95e-2, 6.90e-4),
               "DGNet (discrete gradient / ada. DP)": (3.85e-2, 6.16e-4),
               "DGNet (discrete gradient / discrete gradient)": (3.85e-2, 6.17e-4)},
    "pend": {"NODE (ada. DP / ada. DP)": (5.54e-2, 4.62e0), "HNN (ada. DP / ada. DP)": (4.09e-2, 1.66e-2),
             "SRNN (leapfrog / leapfrog)": (3.92e-2, 1.12e-2),
             "DGNet (discrete gradient / ada. DP)": (3.93e-2, 1.61e-2),
             "DGNet (discrete gradient / discrete gradient)": (3.93e-2, 1.08e-2)},
    "2body": {"NODE (ada. DP / ada. DP)": (2.07e-5, 1.83e-1), "HNN (ada. DP / ada. DP)": (6.21e-6, 8.18e-5),
              "SRNN (leapfrog / leapfrog)": (4.36e-6, 4.04e-5),
              "DGNet (discrete gradient / ada. DP)": (7.80e-6, 8.10e-5),
              "DGNet (discrete gradient / discrete gradient)": (7.80e-6, 8.10e-5)},
    "real": {"NODE (ada. DP / ada. DP)": (1.37e-3, 5.88e-4), "HNN (ada. DP / ada. DP)": (1.41e-3, 3.44e-3),
             "SRNN (leapfrog / leapfrog)": (1.38e-3, 9.63e-3),
             "DGNet (discrete gradient / ada. DP)": (1.38e-3, 4.92e-4),
             "DGNet (discrete gradient / discrete gradient)": (1.38e-3, 5.04e-4)},
}
TASKS = ("spring", "pend", "real", "2body")
T_SPAN, TIMESCALE, TRIALS, TRAJECTORIES = (0.0, 20.0), 5, 15, 50
# their training settings per task (experiment-<task>/train_dgnet.py): optimizer steps (the loop runs
# steps + 1, theirs too), the minibatch (None: full batch) and Adam's L2 weight decay
SETTINGS = {"spring": {"steps": 2000, "batch_size": None, "weight_decay": 1e-4},
            "pend": {"steps": 2000, "batch_size": None, "weight_decay": 1e-4},
            "real": {"steps": 2000, "batch_size": None, "weight_decay": 1e-5},
            "2body": {"steps": 10000, "batch_size": 200, "weight_decay": 0.0}}
# their 2-body data: the original HNN generator called with timesteps=500, t_span=[0, 25] (its other
# arguments at their defaults: 1000 orbits, the first 20% of rows test, solve_ivp's RK45 at rtol 1e-9
# and atol 1e-6, every orbit kept), through ours (hnn.orbits.nbody.orbit_dataset, experiment-2body's sampler)
TWO_BODY = {"num_trials": 1000, "num_points": 500, "t_span": (0.0, 25.0), "test_split": 0.2, "rtol": 1e-9,
            "atol": 1e-6, "min_separation": 0.0}
# how each row predicts; the fixed-step ones take one step per interval of the time grid (``dt`` added)
PREDICT = {"discrete gradient": {"method": "discrete_gradient"},
           "ada. DP": {"method": "dopri5", "rtol": 1e-7, "atol": 1e-9},
           "leapfrog": {"method": "leapfrog"}}
ADAPTIVE = ("ada. DP",)
# the stamp's words for --init (a saved dgnet.json without "init" predates the flag: torch's default biases)
INIT_WORDS = {"zero_bias": "orthogonal weights and zero biases (theirs)",
              "orthogonal": "orthogonal weights and torch's default biases (the original HNN's; theirs: zero biases)",
              "lnn": "the LNN's scaled normal weights and zero biases (theirs: orthogonal, zero biases)"}
# our rows: label -> (kind, objective, how it trains (the table's words), the integrators it predicts with)
ROWS = {"NODE": ("baseline", "trajectory", "RK4 step", ("ada. DP",)),
        "HNN": ("hnn", "trajectory", "RK4 step", ("ada. DP",)),
        "SRNN": ("separable", "trajectory", "leapfrog", ("leapfrog",)),
        "DGNet": ("hnn", "discrete_gradient", "discrete gradient", ("discrete gradient", "ada. DP")),
        "HNN, paper's objective": ("hnn", "derivative", "true dx/dt", ("ada. DP",)),
        # the real pendulum loses energy (0.90 to 0.74 over the test block): a model that may lose it too
        "D-HNN": ("dissipative", "trajectory", "RK4 step", ("ada. DP",))}
ONLY_ON = {"D-HNN": ("real",)}
# --quick: every task and row end to end on one seed, few steps and less data (its budget:
# commands.QUICK_BUDGETS): a ring task's run of 200 steps on their 50 paths took 20 s (2-core box,
# load 7), most of it the full-batch steps. Its runs are named <task>-dgnet-quick (their data differ)
QUICK = {"seeds": 1, "steps": 100}
QUICK_DATA = {"trajectories": 10, "orbits": 100}


def dataset(task: str, seed: int, trajectories: int = TRAJECTORIES, orbits: int = TWO_BODY["num_trials"]) -> dict:
    """Their data for ``task``, with every consecutive pair of states as ``pairs`` (and as one-step
    ``snippets`` for the trajectory objective) and their test twins; ``trajectories`` ring paths
    (spring, pend: theirs 50) or ``orbits`` (2-body: theirs 1000), the first half or 80% to train."""
    system = hnn.load_task(task)
    if task == "real":
        data = system.get_dataset()
        pairs = {key: contiguous_pairs(data[x], data[t], data["dt"]) for key, x, t in (("pairs", "x", "t"),
                                                                                       ("test_pairs", "test_x", "test_t"))}
    elif task == "2body":
        # about a second a seed (1000 orbits, batched), so drawn afresh by each run rather than cached
        data = hnn.orbits.nbody.orbit_dataset(system.random_config, seed, **{**TWO_BODY, "num_trials": orbits})
        points = len(data["t_eval"])
        pairs = {"pairs": pairs_from_paths(data["x"], points), "test_pairs": pairs_from_paths(data["test_x"], points)}
    else:
        data = hnn.datasets.ring_dataset(system.dynamics, seed, trajectories, T_SPAN, TIMESCALE,
                                         system.RADIUS_RANGE, system.NOISE_STD)
        points = len(data["t_eval"])
        pairs = {"pairs": pairs_from_paths(data["x"], points), "test_pairs": pairs_from_paths(data["test_x"], points)}
    return {**data, **pairs, "snippets": pairs["pairs"], "test_snippets": pairs["test_pairs"]}


def contiguous_pairs(x: np.ndarray, t: np.ndarray, dt: float) -> np.ndarray:
    """``[x_n, x_n+1]`` ``(pairs, 2 * dim)`` of the measured states ``x`` ``(n, dim)`` at times ``t``
    ``(n,)`` whose times are ``dt`` apart: the real pendulum's training rows skip frames (10 gaps of
    1/3 or 1/2 s) and the test block (18.5 s), and a pair across a gap would ask for 2-100x the speed."""
    keep = np.isclose(np.diff(t), dt, rtol=1e-6, atol=0.0)
    return np.concatenate([x[:-1][keep], x[1:][keep]], 1)


def _ring_energy(x: torch.Tensor) -> torch.Tensor:
    """Their spring and pendulum metric's energy, q^2 + p^2, ``(..., 2)`` -> ``(...)``."""
    return x[..., 0] ** 2 + x[..., 1] ** 2


def _predict(model, x0: torch.Tensor, t: np.ndarray, predict: str) -> torch.Tensor:
    """``model``'s paths from ``x0`` at ``t`` by the row's integrator ``predict`` (a key of ``PREDICT``)."""
    step = {} if predict in ADAPTIVE else {"dt": float(t[1] - t[0])}
    return hnn.rollout(model, x0, t, **PREDICT[predict], **step)


def energy_mse(task: str, model, seed: int, predict: str, data: dict) -> float:
    """Their energy error of ``model`` rolled out by ``predict`` (see the module docstring)."""
    system = hnn.load_task(task)
    model = hnn.evaluation.float64_copy(model)
    if task == "real":
        t = data["test_t"] - data["test_t"][0]
        x0 = torch.as_tensor(data["test_x"][:1], dtype=torch.float64)
        path = _predict(model, x0, t, predict)[0]
        observed = torch.as_tensor(data["test_x"], dtype=torch.float64)
        return float((system.hamiltonian(observed) - system.hamiltonian(path)).pow(2).mean())
    if task == "2body":
        # their 15 starts exactly (the original's random_config after np.random.seed(0..14)), at every seed,
        # over the data's own grid (500 times of [0, 25]); E is the system's H on both sides
        x0 = torch.as_tensor(np.stack([system.initial_state(i) for i in range(TRIALS)]))
        t = data["t_eval"]
        truth = hnn.rollout(system.dynamics, x0, t, method="dop853", rtol=1e-12, atol=1e-12)
        ours = _predict(model, x0, t, predict)
        return float((system.hamiltonian(truth) - system.hamiltonian(ours)).pow(2).mean())
    rng = np.random.RandomState(10_000 + seed)
    x0 = rng.rand(TRIALS, 2) * 1.6 - 0.8
    x0 += 0.2 * np.sign(x0)
    x0 = torch.as_tensor(x0, dtype=torch.float64)
    t = np.linspace(*T_SPAN, int(TIMESCALE * (T_SPAN[1] - T_SPAN[0])))
    truth = hnn.rollout(system.dynamics, x0, t, method="dop853", rtol=1e-12, atol=1e-12)
    ours = _predict(model, x0, t, predict)
    return float((_ring_energy(truth) - _ring_energy(ours)).pow(2).mean())


def measure(task: str, label: str, seed: int, steps: int, out: Path, init: str = "zero_bias",
            quick: bool = False, device: str = "cpu") -> dict:
    """Train one run of row ``label`` on ``task`` (saved under ``out``/runs) on ``device``, its MLPs
    started by ``init`` (``hnn.models.INITS``; theirs: ``zero_bias``), and measure it on the CPU;
    ``quick``: on ``QUICK_DATA``."""
    kind, objective, _, predicts = ROWS[label]
    trainer = hnn.load_task(task, "train")
    data = dataset(task, seed, **(QUICK_DATA if quick else {}))
    # the trajectory rows' loss is the state error, dt^2 times their derivative error: Adam does not
    # see that scale, but its L2 weight decay adds to the gradient, so it is scaled by dt^2 as well
    decay = SETTINGS[task]["weight_decay"] * (data["dt"] ** 2 if objective == "trajectory" else 1.0)
    config = trainer.Config(name=f"{task}-dgnet" + ("-quick" if quick else ""), model=kind, objective=objective, snippet_steps=1,
                            total_steps=steps, batch_size=SETTINGS[task]["batch_size"], seed=seed,
                            weight_decay=decay, init=init, save_dir=str(out / "runs"), device=device)
    fit = (TrajectoryObjective(dt=data["dt"], loss="l2", method="leapfrog" if kind == "separable" else "rk4",
                               steps=1) if objective == "trajectory" else None)
    run = hnn.runs.find_run(config) or hnn.run_experiment(config, data, fit)
    model, _, metrics = hnn.load_run(run)
    with torch.no_grad():
        pred = model.time_derivative(torch.as_tensor(data["test_x"]))
        derivative = float((pred - torch.as_tensor(data["test_dxdt"])).pow(2).mean())
    return {"run": str(run), "derivative": derivative, "train_seconds": metrics["train_seconds"],
            "energy": {name: energy_mse(task, model, seed, name, data) for name in predicts}}


def measure_job(args: tuple) -> tuple:
    """``((task, label, seed, init), measure(*args))`` on one thread (a worker's task)."""
    with torch_threads(1):      # the caller's count back after: it also runs in the command's own process
        return (*args[:3], args[5]), measure(*args)


def rows_for(task: str) -> list[str]:
    """Our rows on ``task``: all, less the paper's objective where the true dx/dt is not known and
    the rows meant for one task (``ONLY_ON``) elsewhere."""
    return [label for label in ROWS if not (task == "real" and ROWS[label][1] == "derivative")
            and task in ONLY_ON.get(label, (task,))]


def task_table(results: dict, task: str) -> str:
    """The markdown of one ``task`` of ``results`` (``dgnet.json``): the stamp, their rows and ours
    (docs/dgnet.md's section ``dgnet-<task>``, so a run of some tasks leaves the others' sections)."""
    n, steps, meta = results["seeds"], results["steps"][task], results["meta"]
    batch = SETTINGS[task]["batch_size"]
    trained = training_words([run for runs in results["rows"][task].values() for run in runs])
    lines = [f"### {task}", "", generated_by(meta, f"{machine(meta)}, one torch thread a run")
             + f", {meta['seconds']:.0f} s for its tasks ({', '.join(results['tasks'])}){trained}: "
             f"{n} seed(s) of their 15 trials, {steps} steps a run (theirs: {SETTINGS[task]['steps']}) of "
             f"{'the full batch' if batch is None else f'minibatches of {batch}'}, every MLP started with "
             f"{INIT_WORDS[results.get('init', 'orthogonal')]}. Energy: mean over the seeds, "
             "with their median and range; *below theirs*: how many of our seeds score below their published mean of the "
             "same row.", "", "| model (train / predict) | derivative | energy | source | below theirs |",
             "| --- | --- | --- | --- | --- |"]
    lines += [f"| {name} | {d:.2e} | {e:.2e} | published, mean of 15 | |" for name, (d, e) in PUBLISHED[task].items()]
    for label in rows_for(task):
        runs = results["rows"][task][label]
        d = statistics.mean(r["derivative"] for r in runs)
        for predict in ROWS[label][3]:
            energies = [r["energy"][predict] for r in runs]
            spread = f" ({spread_words(energies)})" if n > 1 else ""
            theirs = published_energy(task, label, predict)
            below = "" if theirs is None else f"{sum(e < theirs for e in energies)} of {n}"
            lines.append(f"| ours: {label} ({ROWS[label][2]} / {predict}) | {d:.2e} | "
                         f"{statistics.mean(energies):.2e}{spread} | ours, mean of {n} seeds, {steps} steps | {below} |")
    return "\n".join(lines)


def training_words(runs: list[dict]) -> str:
    """``; its 75 runs trained for 2345 s in all, ...``: the runs' own training seconds summed from their
    saved metrics, so a table published from reused runs still says what they cost; '' where a run's
    record lacks them (a dgnet.json written before they were kept)."""
    seconds = [r.get("train_seconds") for r in runs]
    if not seconds or None in seconds:
        return ""
    return (f"; its {len(runs)} runs trained for {sum(seconds):.0f} s in all (one thread each, whenever each was "
            "trained)")


def spread_words(values: list[float]) -> str:
    """The seeds' median and range in a table cell's words: ``median 1.32e-03, min 4.52e-04, max 4.51e-03``."""
    return f"median {statistics.median(values):.2e}, min {min(values):.2e}, max {max(values):.2e}"


def published_energy(task: str, label: str, predict: str) -> float | None:
    """Their published energy MSE of our row ``label`` predicted by ``predict`` on ``task`` (their row
    of the same name and integrator, whatever it trained through), or None where they have none."""
    return next((e for name, (_, e) in PUBLISHED[task].items()
                 if name.startswith(f"{label} (") and name.endswith(f"/ {predict})")), None)


def table(results: dict) -> str:
    """The markdown of every task of ``results``: their published rows beside ours (the differences:
    this module's docstring)."""
    quick = results["meta"].get("quick_cuts")
    head = [f"**QUICK smoke run** (`--quick`, cut: {'; '.join(quick)}): these numbers test the pipeline, not the "
            "models."] if quick else []
    return "\n\n".join(head + [task_table(results, task) for task in results["tasks"]]) + "\n"


def quick_cuts(tasks, seeds: int | None = None, steps: int | None = None) -> list[str]:
    """What ``--quick`` cuts on ``tasks`` from their protocol, one phrase each (``seeds``, ``steps``:
    the ones given on the command line, which quick keeps), as ``main`` prints them."""
    rings = [task for task in tasks if task in ("spring", "pend")]
    cuts = [f"{QUICK['seeds']} seed of their {TRIALS} trials"] if seeds is None else []
    if steps is None:
        cuts.append(f"{QUICK['steps']} steps a run of their " + ", ".join(f"{SETTINGS[t]['steps']} ({t})" for t in tasks))
    if rings:
        cuts.append(f"{QUICK_DATA['trajectories']} paths of their {TRAJECTORIES} ({', '.join(rings)})")
    if "2body" in tasks:
        cuts.append(f"{QUICK_DATA['orbits']} orbits of their {TWO_BODY['num_trials']} (2body)")
    return cuts
