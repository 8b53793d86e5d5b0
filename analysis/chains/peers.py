"""The peers' published numbers on pendulum chains beside ours, on their own protocols (docs/peers.md).

    python analysis/peers.py --jobs 2 --update-docs      # the whole table, 5 seeds (about 12 hours on 2 cores)
    python analysis/peers.py --device cuda --update-docs # the same on a GPU, each row's seeds as one group
    python analysis/peers.py --quick                      # a smoke run: small data, few steps, N = 1, 2

Trains our model kinds (``kinds()``: every registered one that reads the chain's observed states, from
``hnn.MODEL_KINDS``, so a new kind reaches the table with no edit here) with ``experiment-chain/train.py``'s config on CHNN's protocol (Finzi et al. 2020) for
N = 1, 2, 3, 5 bobs, and on the LNN double pendulum (Cranmer et al. 2020), through
``hnn/sweep.py`` (a rerun reuses every run of the same config); then measures each on its
protocol (``experiment-chain/protocols.py``): CHNN's geometric-mean relative error of the
Cartesian rollout (dopri5 at rtol 1e-7, in float64), mean and median over the test starts, with
the chaos floor; LNN's energy error at T = 100 s. A rollout that blows up is reported by name
with its time, never as a NaN. Writes ``peers.json`` and ``peers.md`` under ``--out``;
``--update-docs`` puts the table into docs/peers.md (full settings only).
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.io import atomic_write
from hnn_analysis import commands
from hnn import sweep, sweep_flags
from hnn_analysis.commands import portable_command
from hnn_analysis.provenance import machine, provenance
from hnn_analysis.training_cost import training_cost

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
# CHNN's budget: 8000 steps of batch 200, their 2000 epochs of 4 batches, on FULL_SEEDS seeds (#45: a verdict
# on several seeds). One seed of it for every kind took about 2.4 hours of a 2-core machine (each kind's
# one-thread rate: docs/peers.md, "What we tried"), so five are about 12 there; on a GPU a row's seeds of one
# kind train as one group (--device cuda). The table of 4000 steps on one seed came first: at N = 2 the
# mechanical kind's mean error went from 2.8e-2 at 1500 steps to 7.2e-3 at 4000
FULL_SEEDS = 5
FULL = {"bobs": BOBS, "fields": {"total_steps": 8000}, "test_starts": 100, "lnn_starts": 40,
        "lnn_fields": {"n_train": 100000, "n_test": 1000, "objective": "derivative", "total_steps": 8000}}


# the peers' own method on its own table: the LNN (Cranmer et al. 2020). The scene studies leave it out
# (``studied=False``: a barely trained black-box L's flow is stiff); here it trains with the LNN's own
# choices (KIND_FIELDS) and its rollouts have a budget (``max_iterations``)
PEER_KINDS = ("lagrangian",)
# what a kind trains with beyond a protocol's fields: the LNN notebook's softplus at lr 1e-3 and its init
# (lnn.py custom_init); at the chain's tanh and 3e-3 its derivative loss diverged on LNN's protocol (2.7e7
# after 300 steps, where softplus at 1e-3 reached 1.4e2 by 2000 steps; measured here)
KIND_FIELDS = {"lagrangian": {"nonlinearity": "softplus", "learn_rate": 1e-3, "init": "lnn"}}
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


def _rollout(chain, kind: str, model, z0: torch.Tensor, t_eval, rtol: float,
             max_iterations: int = MAX_ITERATIONS) -> tuple[torch.Tensor | None, str | None]:
    """The model's path from observed ``z0`` ``(batch, 2N)`` by dopri5 in float64, as Cartesian bobs
    ``(batch, T, 2, N, 2)`` (positions, velocities), or ``(None, why)`` if it blows up. The path of a
    kind on the chain's angles is mapped to the bobs; a Cartesian kind's starts from the bobs and is read as it is."""
    observed = hnn.load_task("chain").observed_coordinates(kind)
    start = chain.to_cartesian(z0) if observed == "cartesian" else z0
    try:
        path = hnn.trajectory.rollout_observed(model.double(), start, t_eval, observed, method="dopri5", rtol=rtol,
                                               atol=rtol, max_iterations=max_iterations)
    except hnn.DivergenceError as err:
        return None, str(err).split(";")[0]
    return (path.reshape(*path.shape[:2], 2, chain.n, 2) if observed == "cartesian" else chain.cartesian(path)), None


def _quiet(kind: str) -> None:
    """A ``measure_*`` caller's progress line for each kind measured: none by default."""


def measure_chnn(chain, models: dict, starts: int, max_iterations: int = MAX_ITERATIONS, said=_quiet) -> dict:
    """CHNN's number ``{kind: {mean, median, n, seconds}}`` and the chaos floor, over ``starts`` test
    starts; ``said(kind)`` after each kind (a progress line)."""
    protocols = hnn.load_task("chain", "protocols")
    spec = protocols.CHNN
    z0 = protocols.chnn_test_starts(chain, starts)
    t = spec["dt"] * np.arange(spec["points"])
    truth = chain.cartesian(hnn.load_task("chain").trajectories(chain, z0, t))
    result = {"floor": protocols.summary(protocols.chaos_floor(chain, z0))}
    for kind, model in models.items():
        pred, blew_up = _rollout(chain, kind, model, z0, t, spec["model_rtol"], max_iterations)
        result[kind] = ({"blew_up": blew_up} if pred is None
                        else protocols.summary(protocols.geometric_mean(protocols.relative_errors(pred, truth))))
        said(kind)
    return result


def measure_lnn(models: dict, starts: int, max_iterations: int = MAX_ITERATIONS, said=_quiet,
                horizon: float | None = None) -> dict:
    """LNN's |E(z^_T) - E(z_T)| / 29.4 at T = 100 s ``{kind: {mean, median, n}}``, dopri5 at rtol 1e-8
    (theirs); ``said(kind)`` after each kind; ``horizon``: T, when not theirs (on their time grid)."""
    data, protocols = hnn.load_task("chain"), hnn.load_task("chain", "protocols")
    chain = data.lnn_double_pendulum()
    z0 = data.sample_lnn_starts(starts, torch.Generator().manual_seed(0), train=False)
    t = protocols.lnn_times()
    t = t if horizon is None else t[t <= horizon]
    true_end = data.trajectories(chain, z0, t, rtol=protocols.LNN["truth_rtol"], atol=protocols.LNN["truth_rtol"])[:, -1]
    result = {}
    for kind, model in models.items():
        pred, blew_up = _rollout(chain, kind, model, z0, t, 1e-8, max_iterations)
        end = None if pred is None else chain.from_cartesian(pred[:, -1])
        result[kind] = ({"blew_up": blew_up} if pred is None
                        else protocols.summary(protocols.energy_error(chain, end, true_end)))
        said(kind)
    return result


def measure(runs: dict, settings: dict, seed: int = 0) -> dict:
    """Every protocol row: ``{"chain<N>": {...}, "lnn": {...}}`` from the trained ``runs``; a kind
    whose training diverged (``sweep.RunFailed.diverged``) is ``{"diverged": message}`` there."""
    data = hnn.load_task("chain")
    rows, budget = {}, settings.get("max_iterations", MAX_ITERATIONS)
    names = [f"chain{n}" for n in settings["bobs"]] + (["lnn"] if settings["lnn_starts"] else [])
    progress = sweep.Progress(sum(len(_loaded(runs, row, settings["kinds"], seed, load=False)) for row in names))
    print(f"  {progress.tag()} measuring {progress.total} models on their protocols", flush=True)

    def said(row: str):
        return lambda kind: print(f"  {progress.advance()} {row}/{kind} measured", flush=True)

    for n in settings["bobs"]:
        models = _loaded(runs, f"chain{n}", settings["kinds"], seed)
        rows[f"chain{n}"] = {**measure_chnn(data.chnn_chain(n), models, settings["test_starts"], budget,
                                            said(f"chain{n}")),
                             **_diverged(runs, f"chain{n}", settings["kinds"], seed),
                             "seconds": _seconds(runs, f"chain{n}", settings["kinds"], seed)}
    if not settings["lnn_starts"]:
        return rows
    models = _loaded(runs, "lnn", settings["kinds"], seed)
    rows["lnn"] = {**measure_lnn(models, settings["lnn_starts"], budget, said("lnn"), settings.get("lnn_horizon")),
                   **_diverged(runs, "lnn", settings["kinds"], seed),
                   "seconds": _seconds(runs, "lnn", settings["kinds"], seed)}
    return rows


def _diverged(runs: dict, row: str, kinds, seed: int) -> dict:
    """``{kind: {"diverged": the error's type, step and first clause}}`` for the kinds of ``row`` whose model
    failed in training, e.g. ``'SingularLagrangianError at training step 0 of 4000: LagrangianNN: d2L/dqdot2
    is singular at 1 states'`` (the states themselves are in the run's log)."""
    found = {kind: runs.get(f"{row}/{kind}/seed{seed}") for kind in kinds}
    return {kind: {"diverged": err.message.split(", where")[0].replace(": at ", " at ", 1)}
            for kind, err in found.items() if isinstance(err, sweep.RunFailed) and err.diverged}


def _loaded(runs: dict, row: str, kinds, seed: int, load: bool = True) -> dict:
    """``{kind: its trained model}`` of ``row`` (``load=False``: its run folder)."""
    found = {kind: runs.get(f"{row}/{kind}/seed{seed}") for kind in kinds}
    return {kind: hnn.load_run(folder)[0] if load else folder for kind, folder in found.items()
            if isinstance(folder, Path)}


def _seconds(runs: dict, row: str, kinds, seed: int) -> dict:
    """Each kind's training cost on one quiet thread (``hnn_analysis.training_cost``: its steps at the
    rate of short timed bursts of the same config), not the run's wall time, which counts whatever else
    the machine did meanwhile (kept as ``wall``)."""
    found = {kind: runs.get(f"{row}/{kind}/seed{seed}") for kind in kinds}
    out = {}
    for kind, folder in found.items():
        if isinstance(folder, Path):
            cost = training_cost("chain", hnn.load_run(folder)[1])
            out[kind] = {**cost, "wall": json.loads((folder / "metrics.json").read_text()).get("train_seconds")}
    return out


def curves(runs: dict, settings: dict, seed: int = 0) -> dict:
    """Each run's held-out loss against training: ``{row: {kind: {"epochs": [...], "test_loss": [...]}}}``,
    from the saved histories (a test batch every ``print_every`` steps); x in CHNN's epochs of 800
    snippets (4 steps of batch 200) for the chain rows, in steps for the LNN row."""
    rows = [f"chain{n}" for n in settings["bobs"]] + (["lnn"] if settings["lnn_starts"] else [])
    out = {}
    for row in rows:
        for kind in settings["kinds"]:
            folder = runs.get(f"{row}/{kind}/seed{seed}")
            if not isinstance(folder, Path):
                continue
            history = json.loads((folder / "metrics.json").read_text())["history"]
            per_epoch = 1.0 if row == "lnn" else 800 / 200
            out.setdefault(row, {})[kind] = {"epochs": [step / per_epoch for step in history["test_steps"]],
                                             "test_loss": history["test_loss"]}
    return out


def curves_figure(found: dict, path: Path) -> Path:
    """docs/figures/peers-curves.png: one panel per protocol row, the held-out loss of each kind (log axis)."""
    from matplotlib.ticker import NullFormatter

    from hnn_analysis.plotting import save_figure     # first: it sets the Agg backend
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(found), figsize=(3.3 * len(found), 3.0), squeeze=False)
    for ax, (row, by_kind) in zip(axes[0], found.items()):
        for kind, curve in by_kind.items():
            ax.plot(curve["epochs"], curve["test_loss"], label=kind, lw=1.2)
        ax.set_yscale("log")
        ax.yaxis.set_minor_formatter(NullFormatter())     # labelled minor ticks overlap on a short decade
        ax.set_title(f"N = {row[len('chain'):]}, CHNN protocol" if row.startswith("chain") else "LNN double pendulum",
                     fontsize=9)
        ax.set_xlabel("epochs (800 snippets)" if row.startswith("chain") else "steps (batch of states)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0][0].set_ylabel("held-out loss (snippet MAE; LNN: dx/dt MSE, its lagrangian kind L1)", fontsize=8)
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)


def over_seeds(by_seed: dict) -> dict:
    """The rows of several seeds (``{seed: measure(...)}``) as one: per kind the mean over the seeds of each
    seed's mean error, ``seeds`` (each seed's mean, in seed order), ``low``/``high`` (their range) and ``se``
    (their standard error), the median of the seeds' medians, and ``failed`` (``{seed: why}``: blew up or
    diverged in training); a kind no seed measured keeps the first seed's failure. The chaos floor and the
    training seconds are the first seed's (the same starts and config)."""
    first = by_seed[min(by_seed)]
    out = {}
    for row, entries in first.items():
        merged = {"floor": entries.get("floor"), "seconds": entries.get("seconds", {})}
        kinds = {k for rows in by_seed.values() for k in rows[row] if k not in ("floor", "seconds")}
        for kind in sorted(kinds):
            found = {seed: rows[row].get(kind) for seed, rows in sorted(by_seed.items())}
            means = {seed: e["mean"] for seed, e in found.items() if e and "mean" in e}
            failed = {seed: e.get("blew_up") or e.get("diverged") for seed, e in found.items() if e and "mean" not in e}
            if not means:
                merged[kind] = next(e for e in found.values() if e)
                continue
            values = np.array(list(means.values()))
            merged[kind] = {"mean": float(values.mean()), "seeds": [float(v) for v in values],
                            "low": float(values.min()), "high": float(values.max()),
                            "se": float(values.std(ddof=1) / np.sqrt(len(values))) if len(values) > 1 else 0.0,
                            "median": float(np.median([found[s]["median"] for s in means])),
                            "n": found[next(iter(means))]["n"], "failed": failed}
        out[row] = merged
    return out


def _cell(entry: dict | None) -> str:
    if entry is None:
        return "not trained"
    if "blew_up" in entry:
        return f"blew up: {entry['blew_up']}"
    if "diverged" in entry:
        return f"failed in training: {entry['diverged']}"
    if len(entry.get("seeds", ())) > 1:         # the mean over seeds, their range and how many
        failed = f"; {len(entry['failed'])} more failed" if entry.get("failed") else ""
        return f"{entry['mean']:.2e} ({entry['low']:.1e}..{entry['high']:.1e}, {len(entry['seeds'])} seeds{failed})"
    return f"{entry['mean']:.2e} ({entry['median']:.2e})"


def _seeds_sentence(seeds) -> str:
    if len(seeds) == 1:
        return f"One seed ({seeds[0]}) a kind: each cell is that run's mean (median) over the test starts."
    return (f"{len(seeds)} seeds ({seeds[0]}..{seeds[-1]}) a kind: each cell is the mean over the seeds of each "
            "seed's mean over the test starts, with the seeds' range.")


def markdown(results: dict) -> str:
    """The generated section of docs/peers.md: the peers' numbers beside ours, same metric."""
    published = hnn.load_task("chain", "protocols").CHNN_PUBLISHED
    meta = results["meta"]
    names = meta["kinds"]
    lines = []
    if meta["quick"]:
        lines += ["**QUICK smoke run** (`--quick`: small data, few steps, few test starts): these numbers test the "
                  "pipeline and say nothing about the kinds; the full table comes from `python analysis/peers.py "
                  "--jobs 2 --update-docs`." + (" Cut: " + "; ".join(meta["quick_cuts"]) + "."
                                                if meta.get("quick_cuts") else ""), ""]
    walls = [s["wall"] for row in results["rows"].values() for s in row["seconds"].values() if s.get("wall")]
    reused = meta.get("reused", 0)
    if not meta["seconds"]["training"]:
        trained = f"every run reused (their recorded training wall times sum to {sum(walls):.0f} s)"
    elif reused:        # a rerun after an interruption: say what this sitting trained, and what the table holds
        trained = (f"training {meta['seconds']['training']:.0f} s for {meta['trained']} runs, {reused} reused from an "
                   f"earlier sitting (every run's recorded training wall time: {sum(walls):.0f} s in all)")
    else:
        trained = f"training {meta['seconds']['training']:.0f} s"
    lines += [f"From `{meta['command']}` at commit {meta.get('commit', '?')} ({machine(meta)}); "
              f"{trained}, measuring {meta['seconds']['measuring']:.0f} s. Training seconds in the tables: each "
              "run's steps at the rate of short bursts of the same config alone on one thread (what it costs on a "
              "quiet core; its recorded wall time is in peers.json). "
              f"Each CHNN-protocol kind trains {meta['steps']} steps of batch 200, {meta['steps'] / 4:g} of CHNN's "
              "epochs of 800 snippets (theirs: 2000), by "
              f"{meta.get('optimizer', 'adam')} with a {meta.get('schedule', 'constant')} learning rate (theirs: AdamW, "
              "cosine). " + _seeds_sentence(meta.get("seeds", [0])) +
              " Training curves: [figures/peers-curves.png](figures/peers-curves.png).", "",
              "### CHNN protocol (Finzi et al. 2020): geometric-mean relative error of the Cartesian rollout, "
              "mean (median) over the test starts", "",
              "| N | published HNN (mechanical) | published CHNN | published CLNN | published NeuralODE | published floor | "
              + " | ".join(f"ours: {kind}" for kind in names) + " | our floor | our training s (one thread) |",
              "| --- " * (7 + len(names)) + "| --- |"]
    for name, row in results["rows"].items():
        if not name.startswith("chain"):
            continue
        n = int(name[len("chain"):])
        peer = published.get(n, {})
        seconds = ", ".join(f"{kind} {s['seconds']:.0f}" for kind, s in row["seconds"].items())
        lines.append(f"| {n} | " + " | ".join(
            f"{peer[k][0]:.2e} ({peer[k][1]:.2e})" if k in peer else "" for k in ("HNN", "CHNN", "CLNN", "NeuralODE", "floor"))
            + " | " + " | ".join(_cell(row.get(kind)) for kind in names)
            + f" | {_cell(row['floor'])} | {seconds} |")
    lines += card(results)
    lnn = results["rows"].get("lnn")
    if lnn is not None:
        lnn_published = hnn.load_task("chain", "protocols").LNN_PUBLISHED
        horizon = meta.get("lnn_horizon") or hnn.load_task("chain", "protocols").LNN["t_end"]
        lines += ["", f"### LNN double pendulum (Cranmer et al. 2020): |E(z^_T) - E(z_T)| / 29.4 at T = {horizon:g} s, "
                  "mean (median) over the starts (ours: dopri5 at rtol 1e-8)", "",
                  "| kind | energy error | training steps | training s (one thread) |", "| --- | --- | ---: | ---: |"]
        lines += [f"| published {k} | {v:.2g} | | |" for k, v in lnn_published.items()]
        lines += [f"| ours: {kind} | {_cell(lnn.get(kind))} | "
                  + (f"{lnn['seconds'][kind]['steps'] - 1} | {lnn['seconds'][kind]['seconds']:.0f} |"
                     if kind in lnn["seconds"] else " | |") for kind in names]
    return "\n".join(lines) + "\n"


def inseparable(row: dict, best: str, kinds) -> list[str]:
    """The kinds of ``kinds`` whose seeds' range of mean errors overlaps ``best``'s (``over_seeds``): the
    seeds cannot tell them from the best. Empty with one seed, where nothing is separated by seeds."""
    if len(row[best].get("seeds", ())) < 2:
        return []
    return [kind for kind in kinds if kind != best and len(row[kind].get("seeds", ())) > 1
            and row[kind]["low"] <= row[best]["high"]]


def card(results: dict) -> list[str]:
    """The chain card's lines: at each N the best kind on the mean (over seeds where there are several), the
    kind that is enough, the one of least training seconds (one thread) whose mean is within 2x of the best,
    and the kinds the seeds cannot separate from the best (their ranges overlap)."""
    lines = ["", "### Which kind a chain requires (the card)", "",
             "The best of our kinds on the mean error at each N (the mean over seeds), and the one that is enough: "
             "of the kinds within 2x of the best, the one that trains in the fewest seconds (one thread). With "
             "several seeds, the last column names the kinds whose seeds' range of errors overlaps the best's: "
             "the seeds cannot say which of them is better (with one seed it says nothing).", "",
             "| N | best | enough (within 2x, fewest training s) | all within 2x | seeds cannot separate from the best |",
             "| --- | --- | --- | --- | --- |"]
    for name, row in results["rows"].items():
        if not name.startswith("chain"):
            continue
        means = {kind: row[kind]["mean"] for kind in results["meta"]["kinds"] if "mean" in row.get(kind, {})}
        if not means:
            continue
        best = min(means, key=means.get)
        near = [kind for kind in means if means[kind] <= 2 * means[best]]
        seconds = {kind: row["seconds"].get(kind, {}).get("seconds", float("inf")) for kind in near}
        enough = min(near, key=seconds.get)
        tied = inseparable(row, best, means) if len(row[best].get("seeds", ())) > 1 else None
        lines.append(f"| {name[len('chain'):]} | {best} {means[best]:.2e} | {enough} {means[enough]:.2e}, "
                     f"{seconds[enough]:.0f} s | {', '.join(sorted(near, key=means.get))} | "
                     f"{'one seed: not tested' if tied is None else ', '.join(tied) or 'none'} |")
    return lines


def _parser() -> argparse.ArgumentParser:
    p = hnn.cli.Parser(prog="peers.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    commands.add_flags(p, quick="a smoke run of every stage: small data, 100 steps (the LNN too), N = 1, 2; "
                       + commands.budget_words("peers"),
                       out="output folder (default: results/peers, or results-quick/peers with --quick)",
                       jobs="worker processes (1: in this process)")
    p.add_argument("--seed", type=hnn.cli.int_at_least(0), default=0, help="the first seed")
    p.add_argument("--seeds", type=hnn.cli.int_at_least(1), default=None,
                   help="seeds seed .. seed + seeds - 1 of every run, the tables' means over them with their range "
                        f"(default: {FULL_SEEDS} for the full table, 1 with --quick)")
    sweep_flags.add_backend_flags(p)
    commands.add_flags(p, update_docs="write the table into docs/peers.md (full settings only)")
    return p


def main(argv=None, settings: dict | None = None) -> dict:
    """Train, measure, write; ``settings`` replaces ``FULL`` / ``QUICK`` (the tests' tiny config)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _parser()
    args = parser.parse_args(argv)
    if args.update_docs and (args.quick or settings is not None):
        parser.error("--update-docs writes full-settings results into docs/peers.md; drop --quick")
    sweep_flags.check_backend(parser, args)
    full = settings is None and not args.quick
    settings = {"kinds": kinds(), **(settings or (QUICK if args.quick else FULL))}
    out = args.out or hnn.tasks.repo_root() / ("results-quick" if args.quick else "results") / "peers"
    cuts = quick_cuts(settings) if args.quick and not full else []
    if cuts:
        commands.say_quick("peers", cuts)
    seeds = range(args.seed, args.seed + (args.seeds or (FULL_SEEDS if full else 1)))
    jobs = plan_seeds(settings, out, seeds)
    runs, todo = sweep.reuse(jobs)
    print(f"peers: {len(runs)} runs reused, {len(todo)} to train", flush=True)
    trained, seconds = sweep.train_jobs(todo, args.jobs, out / "logs", args.backend, args.ray_address,
                                        device=args.device)
    runs.update(trained)
    tic = time.perf_counter()
    by_seed = {seed: measure(runs, settings, seed) for seed in seeds}
    rows = over_seeds(by_seed) if len(seeds) > 1 else by_seed[args.seed]
    found = curves(runs, settings, args.seed)
    if found:
        figure = curves_figure(found, out / "figures" / "peers-curves.png")
        if args.update_docs:
            target = hnn.tasks.repo_root() / "docs" / "figures" / "peers-curves.png"
            atomic_write(target, lambda tmp: shutil.copyfile(figure, tmp))
    results = {"meta": {**provenance(), "command": portable_command(argv, "analysis/peers.py"),
                        "quick": not full,     # --quick or a test's settings: not the table
                        "quick_cuts": cuts, "lnn_horizon": settings.get("lnn_horizon"),
                        "reused": len(jobs) - len(todo), "trained": len(todo),
                        "kinds": list(settings["kinds"]), "seeds": list(seeds),
                        "steps": jobs[0].config.total_steps if jobs else None,
                        "optimizer": jobs[0].config.optimizer if jobs else None,
                        "schedule": jobs[0].config.schedule if jobs else None,
                        "seconds": {"training": seconds["training"], "measuring": time.perf_counter() - tic}},
               "rows": rows, "by_seed": by_seed if len(seeds) > 1 else None, "curves": found}
    text = markdown(results)
    commands.publish(out, "peers", results, text, {"peers": text} if args.update_docs else {})
    # a model that failed in training is a result of its config (its table cell says how), not a broken run
    sweep.exit_if_failed({key: outcome for key, outcome in runs.items()
                          if not (isinstance(outcome, sweep.RunFailed) and outcome.diverged)})
    return results
