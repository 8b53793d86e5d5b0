"""The peers' table's settings and runs: the chain sizes, the full and quick settings, each kind's own
fields on each protocol, the kinds it trains (``kinds``), the sweep's jobs (``plan``) and what
``--quick`` cuts (``quick_cuts``). ``analysis/peers.py`` is its command (docs/peers.md).
"""
from __future__ import annotations

import fnmatch
from pathlib import Path

import hnn
from hnn.sweeps import sweep

BOBS = (1, 2, 3, 5)
# --quick: a smoke run of every stage within its budget (commands.QUICK_BUDGETS); its LNN trains the
# protocol's steps (lnn_fields), not its kind's own 60000 (LNN_KIND_FIELDS), and says so (quick_cuts).
# Its rollouts stop at 1000 iterations: a model of 100 steps rolled out over the LNN protocol's 100 s
# took up to a minute (2-core box, load 7) to reach 5000 and be reported as too stiff; its energy error
# is at T = 10 s (lnn_horizon): the truth alone to their T = 100 s (rtol 1e-10) took 25 s
QUICK = {"bobs": (1, 2), "fields": {"n_train": 50, "n_test": 10, "hidden_dim": 64, "total_steps": 100},
         "max_iterations": 1000,
         "test_starts": 10, "lnn_starts": 2, "lnn_fields": {"n_train": 2000, "n_test": 200, "hidden_dim": 64,
                                                           "total_steps": 100},
         "lnn_kind_fields": {"lagrangian": {"derivative_loss": "l1"}}, "lnn_horizon": 10.0}
# --quick's declared costs on the reference box (hnn_analysis.plan; reference_plan), in seconds, each run's own
# from peers.py --quick on a quiet 2-core box (quick_budgets.py at 643e3a4, load 1.0 with it: 106 s in all): a
# CHNN-row run's training, its data read and model built (train_run: the hnn, second_order and baseline kinds'
# 0.6-0.9 s at N = 1 and 2) and a bob's steps by kind, where they grow with the bobs (the Lagrangian kinds' Hessians:
# lagrangian 5.8 s at N = 1, 10.4 at N = 2; mechanical 3.2, 3.7; constrained 2.6, 2.4; constrained_lagrangian
# 1.6, 2.4); an LNN-protocol run's training (0.1-0.6 s: 1.7 s for its 7 runs); a run's measuring, a bob on the
# CHNN rows (9 s over the 7 runs of N = 1, 20 s over the 14 bobs of N = 2) and an LNN run's (17 s for 7: its truth
# to T = lnn_horizon at rtol 1e-10); the table's one-thread timing of the kinds (8 s). The costs of 36c2ac2 came
# from a box at load 2 and planned 172 s for these 106 (measuring 97 s for 48): a stage's estimate is held within
# 1.5x of its time on a quiet box (docs/speed.md, "Quick modes and their budgets"). A run is measured in the sitting
# that trains the next one beside it, so its seconds depend on what the other worker trains meanwhile: at 7b4a1a2
# (quiet box, 2026-12-06) the same measuring took 11 s for N = 1, 29 s for N = 2's 14 bobs and 41 s for the 7 LNN
# runs (83 s in all, against 55 s at 4f8f65b), and the timing 11.4 s (9.3): the costs sit between the runs seen
QUICK_COSTS = {"train_bob": {"lagrangian": 5.0, "mechanical": 2.0, "constrained": 1.4, "constrained_lagrangian": 0.95},
               "train_run": 0.7, "train_lnn": 0.25, "measure_bob": 1.7, "measure_lnn": 4.0, "timing": 10.0}
# CHNN's budget: 8000 steps of batch 200, their 2000 epochs of 4 batches, on FULL_SEEDS seeds (#45: a verdict
# on several seeds). One seed of it for every kind is about 7.8 hours of one thread (each kind's one-thread
# rate, docs/peers.md; the LNN's chain rows, which train from lnn_convex, and its 60000 protocol steps
# included), so five are about 20 hours of a 2-core machine; on a GPU a row's seeds of one kind train as
# one group (--device cuda). The table of 4000 steps on one seed came first: at N = 2 the
# mechanical kind's mean error went from 2.8e-2 at 1500 steps to 7.2e-3 at 4000
FULL_SEEDS = 5
FULL = {"bobs": BOBS, "fields": {"total_steps": 8000}, "test_starts": 100, "lnn_starts": 40,
        "lnn_fields": {"n_train": 100000, "n_test": 1000, "objective": "derivative", "total_steps": 8000}}


# the peers' own method on its own table: the LNN (Cranmer et al. 2020). The scene studies leave it out
# (``studied=False``: a barely trained black-box L's flow is stiff); here it trains with the LNN's own
# choices (KIND_FIELDS) and its rollouts have a budget (``max_iterations``)
PEER_KINDS = ("lagrangian",)
# what a kind trains with beyond a protocol's fields: the LNN notebook's softplus at lr 1e-3, its init
# (lnn.py custom_init) and its solve for qddot, the pseudo-inverse of d2L/dqdot2 (lnn.py lagrangian_eom:
# jnp.linalg.pinv), which trains on through states where the plain solve stopped 12 of the 15 runs at
# N = 2, 3, 5 (docs/stress.md, "The LNN solved as its authors solve it"); at the chain's tanh and 3e-3 its
# derivative loss diverged on LNN's protocol (2.7e7 after 300 steps, where softplus at 1e-3 reached 1.4e2
# by 2000 steps; measured here)
KIND_FIELDS = {"lagrangian": {"nonlinearity": "softplus", "learn_rate": 1e-3, "init": "lnn", "lnn_solve": "pinv"}}
# and on the LNN protocol's derivatives its notebook's L1 loss, with a budget of its own: its L1 fit keeps
# improving while the rate is high (held-out dx/dt MSE 106 and energy error 0.30 after 8000 steps with the
# rate annealed by then; 0.023 and 0.0026 after 60000, one run each: docs/peers.md, "The LNN on its own protocol")
LNN_KIND_FIELDS = {"lagrangian": {"derivative_loss": "l1", "total_steps": 60000}}
# and on CHNN's snippets an init whose L starts convex in qdot: from the LNN's own init its first RK4
# snippets left the data's range (accelerations to 10^5) and training failed at step 0 in 1, 4 and 5 of 5
# seeds at N = 1, 3, 5; from lnn_convex none did (docs/stress.md, "The LNN's start")
CHNN_KIND_FIELDS = {"lagrangian": {"init": "lnn_convex"}}
# dopri5 iterations a model's rollout may take before it is reported as too stiff to finish: far above
# what a trained model's rollouts take, reached only by a flow that forces tiny steps
MAX_ITERATIONS = 100_000


def kinds() -> tuple[str, ...]:
    """The kinds the table trains: every one that the chain task's ``--model`` takes and whose model
    reads its observed states [q, qdot] (as they are, or mapped: ``hnn.kinds.ModelKind.reads``), or else the
    bobs' Cartesian [x, xdot] (the constrained kinds: ``experiment-chain/data.py``'s
    ``observed_coordinates``), and whose declared structure the chain has (``structure_holds``: no
    friction, no H = T(p) + V(q)). The LNN protocol trains the same kinds on derivatives of the same states."""
    config, chain = hnn.load_task("chain", "train").Config, hnn.load_task("chain")
    return tuple(kind for kind in hnn.cli.model_choices(config)
                 if (hnn.MODEL_KINDS[kind].studied or kind in PEER_KINDS) and chain.structure_holds(kind)
                 and any(hnn.MODEL_KINDS[kind].reads(observed) for observed in ("velocity", "cartesian")))


def plan_seeds(settings: dict, out: Path, seeds) -> list[sweep.Job]:
    """``plan``'s jobs for every seed of ``seeds``: the sweep groups a row's seeds of one kind (``--group``)."""
    return [job for seed in seeds for job in plan(settings, out, seed)]


def plan(settings: dict, out: Path, seed: int = 0) -> list[sweep.Job]:
    """One ``sweep.Job`` per (protocol row, kind): ``chain<N>/<kind>/seed<seed>`` and ``lnn/<kind>/seed<seed>``."""
    jobs = []
    for n in settings["bobs"]:
        for kind in settings["kinds"]:
            fields = {"bobs": n, "model": kind, "seed": seed, "save_dir": str(out / "runs"), **settings["fields"],
                      **KIND_FIELDS.get(kind, {}), **CHNN_KIND_FIELDS.get(kind, {})}
            jobs.append(sweep.Job(f"chain{n}/{kind}/seed{seed}", "chain", hnn.tasks.task_config("chain", fields)))
    for kind in settings["kinds"] if settings["lnn_starts"] else ():
        fields = {"bobs": 2, "protocol": "lnn", "objective": "derivative", "model": kind, "seed": seed,
                  "save_dir": str(out / "runs"), **settings["lnn_fields"], **KIND_FIELDS.get(kind, {}),
                  **settings.get("lnn_kind_fields", LNN_KIND_FIELDS).get(kind, {})}
        jobs.append(sweep.Job(f"lnn/{kind}/seed{seed}", "chain", hnn.tasks.task_config("chain", fields)))
    return jobs


def select(jobs: list[sweep.Job], patterns: list[str] | None) -> list[sweep.Job]:
    """The jobs whose name matches one of the shell ``patterns`` (``--only``; None: all); ValueError
    for a pattern that names no job."""
    for pattern in patterns or ():
        if not any(fnmatch.fnmatchcase(job.key, pattern) for job in jobs):
            rows = ", ".join(dict.fromkeys(job.key.split("/")[0] for job in jobs))
            raise ValueError(f"--only {pattern!r} matches no run of this plan; its runs are named like "
                             f"{jobs[0].key} (row/kind/seed), of rows {rows}")
    return [job for job in jobs if patterns is None or any(fnmatch.fnmatchcase(job.key, p) for p in patterns)]


def quick_cuts(quick: dict = QUICK, full: dict = FULL) -> list[str]:
    """What ``quick`` settings cut from ``full``, one phrase each, as the command prints them."""
    config = hnn.load_task("chain", "train").Config
    chnn = {**{k: getattr(config, k) for k in ("n_train", "n_test", "hidden_dim", "total_steps")}, **full["fields"]}
    lnn = {**chnn, **full["lnn_fields"]}
    steps = {kind: f.get("total_steps") for kind, f in LNN_KIND_FIELDS.items() if f.get("total_steps")}
    cuts = [f"N = {', '.join(map(str, quick['bobs']))} of {', '.join(map(str, full['bobs']))} bobs",
            f"1 seed of {FULL_SEEDS} (--seeds sets it)"]
    words = {"n_train": "training paths", "n_test": "test paths", "hidden_dim": "hidden units",
             "total_steps": "training steps"}
    cuts += [f"CHNN protocol: {quick['fields'][k]} {w} of {chnn[k]}" for k, w in words.items() if k in quick["fields"]]
    cuts.append(f"CHNN protocol: {quick['test_starts']} test starts of {full['test_starts']}")
    lnn_words = {**words, "n_train": "training states", "n_test": "test states"}
    cuts += [f"LNN protocol: {quick['lnn_fields'][k]} {w} of {lnn[k]}" for k, w in lnn_words.items()
             if k in quick["lnn_fields"]]
    cuts += [f"LNN protocol: its {kind} kind {quick['lnn_fields']['total_steps']} steps of its own {n}"
             for kind, n in steps.items()
             if quick.get("lnn_kind_fields", LNN_KIND_FIELDS).get(kind, {}).get("total_steps") is None]
    cuts.append(f"LNN protocol: {quick['lnn_starts']} energy starts of {full['lnn_starts']}")
    if quick.get("lnn_horizon"):
        cuts.append(f"LNN protocol: the energy error at T = {quick['lnn_horizon']:g} s of their "
                    f"{hnn.load_task('chain', 'protocols').LNN['t_end']:g} s")
    if "max_iterations" in quick:
        cuts.append(f"rollouts stop at {quick['max_iterations']} dopri5 iterations (full: {MAX_ITERATIONS})")
    return cuts


def quick_training(job, costs: dict = QUICK_COSTS) -> float:
    """A --quick run's declared training seconds on the reference box (``QUICK_COSTS``): an LNN-protocol run's, or
    a CHNN-row run's (its data read, its model built) and its kind's steps a bob."""
    if job.key.startswith("lnn/"):
        return costs["train_lnn"]
    return costs["train_run"] + costs["train_bob"].get(job.config.model, 0.0) * job.config.bobs


def quick_measuring(job, costs: dict = QUICK_COSTS) -> float:
    """A --quick run's declared measuring seconds on the reference box (``QUICK_COSTS``): an LNN-protocol run's
    energy error, or a CHNN-row run's rollouts at its bobs."""
    return costs["measure_lnn"] if job.key.startswith("lnn/") else costs["measure_bob"] * job.config.bobs


def reference_plan(settings: dict | None = None, costs: dict = QUICK_COSTS) -> list:
    """``peers.py --quick``'s plan on the quick budgets' reference box (``hnn_analysis.plan``: declared costs,
    nothing built): the plan's own timing of its configs (``plans.reference_timing``), its datasets (one a CHNN
    row, the chain's ``TaskSpec.data_cost``: the LNN protocol's states are drawn with their derivatives, no
    rollout, 0.0 s), its training and measuring (each run's ``quick_training`` and ``quick_measuring``) and the
    table's timing of the kinds."""
    from hnn_analysis import plan as plans
    settings = {"kinds": kinds(), **(settings or QUICK)}
    jobs = plan(settings, Path("runs"))
    rows = len(settings["bobs"])
    return [plans.reference_timing(jobs), plans.Stage("build", rows, "datasets", rows * hnn.task_spec("chain").data_cost,
                        "the chain's declared build a CHNN row, on the reference box"),
            plans.Stage("train", len(jobs), "runs", sum(quick_training(job, costs) for job in jobs),
                        "each run's declared cost by kind and bobs"),
            plans.Stage("measure", len(jobs), "runs' rollouts", sum(quick_measuring(job, costs) for job in jobs),
                        "each run's declared measuring"),
            plans.Stage("time", len(settings["kinds"]), "kinds", costs["timing"], "the table's one-thread rates")]
