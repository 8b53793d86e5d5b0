"""The peers' table measured: each protocol's metric on the trained chain models (CHNN's geometric-mean
relative error of the Cartesian rollout, with the chaos floor; the LNN's energy error), each kind's
training cost and loss curves, and the means over seeds. A rollout that blows up is reported by name
with its time, never as a NaN.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.sweeps import sweep
from hnn_analysis.chains.peer_plan import MAX_ITERATIONS
from hnn_analysis.training_cost import training_cost


def _rollout(chain, kind: str, model, z0: torch.Tensor, t_eval, rtol: float,
             max_iterations: int = MAX_ITERATIONS) -> tuple[torch.Tensor | None, str | None]:
    """The model's path from observed ``z0`` ``(batch, 2N)`` by dopri5 in float64, as Cartesian bobs
    ``(batch, T, 2, N, 2)`` (positions, velocities), or ``(None, why)`` if it blows up. The path of a
    kind on the chain's angles is mapped to the bobs; a Cartesian kind's starts from the bobs and is read as it is."""
    observed = hnn.load_task("chain").observed_coordinates(kind)
    start = chain.to_cartesian(z0) if observed == "cartesian" else z0
    try:
        path = hnn.objectives.trajectory.rollout_observed(model.double(), start, t_eval, observed, method="dopri5", rtol=rtol,
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
    print(f"  {progress.tag()} measuring {progress.total} model{'' if progress.total == 1 else 's'} on their protocols",
          flush=True)

    def said(row: str):
        return lambda kind: print(f"  {progress.advance()} {row}/{kind}/seed{seed} measured", flush=True)

    for n in settings["bobs"]:
        models = _loaded(runs, f"chain{n}", settings["kinds"], seed)
        rows[f"chain{n}"] = {**measure_chnn(data.chnn_chain(n), models, settings["test_starts"], budget,
                                            said(f"chain{n}")),
                             **_diverged(runs, f"chain{n}", settings["kinds"], seed)}
    if not settings["lnn_starts"]:
        return rows
    models = _loaded(runs, "lnn", settings["kinds"], seed)
    rows["lnn"] = {**measure_lnn(models, settings["lnn_starts"], budget, said("lnn"), settings.get("lnn_horizon")),
                   **_diverged(runs, "lnn", settings["kinds"], seed)}
    return rows


def one_thread() -> None:
    """A measuring worker's initializer: one torch thread (the workers share the machine's cores)."""
    torch.set_num_threads(1)


def _diverged(runs: dict, row: str, kinds, seed: int) -> dict:
    """``{kind: {"diverged": the error's type, step and first clause}}`` for the kinds of ``row`` whose model
    failed in training, e.g. ``'SingularLagrangianError at training step 0 of 4000: LagrangianNN: d2L/dqdot2
    is singular at 1 states'`` (the states themselves are in the run's log)."""
    found = {kind: runs.get(f"{row}/{kind}/seed{seed}") for kind in kinds}
    return {kind: diverged_entry(err) for kind, err in found.items() if isinstance(err, sweep.RunFailed) and err.diverged}


def diverged_entry(err: sweep.RunFailed) -> dict:
    """The table's entry of a run that failed in training: ``{"diverged": its error's type, step and first clause}``.

    One shape for every ``hnn.DivergenceError``: an LNN whose d2L/dqdot2 is singular to round-off stops in its
    solve (``SingularLagrangianError at training step 0 of 2: LagrangianNN: d2L/dqdot2 is singular at 3
    states``), one where it is merely near-singular in its snippet's RK4 (``DivergenceError at training step 1
    of 2: rk4 (dt=0.03, max_norm=1000000.0): 1 trajectories diverged: #26 at t=0.09``), which of them depends on
    the machine's round-off; each message's advice (after ``, where`` or its first sentence) is in the run's log."""
    return {"diverged": err.message.split(", where")[0].split(". ")[0].replace(": at ", " at ", 1)}


def _loaded(runs: dict, row: str, kinds, seed: int, load: bool = True) -> dict:
    """``{kind: its trained model}`` of ``row`` (``load=False``: its run folder)."""
    found = {kind: runs.get(f"{row}/{kind}/seed{seed}") for kind in kinds}
    return {kind: hnn.load_run(folder)[0] if load else folder for kind, folder in found.items()
            if isinstance(folder, Path)}


def add_seconds(by_seed: dict, jobs: list, walls: dict) -> dict:
    """``by_seed`` (``{seed: {row: {kind: entry}}}``) with each row's ``seconds``: per kind whose run was
    saved (its recorded wall time in ``walls``, by run key), its training cost on one quiet thread
    (``hnn_analysis.training_cost``: its config's steps at the rate of short timed bursts), not the run's
    wall time, which counts whatever else the machine did meanwhile (kept as ``wall``). Timed here, in
    this process, after every rollout: nothing else runs. A kind whose timing bursts (a fresh model's
    first steps) fail in training where its run did not is left untimed, and said so."""
    for job in jobs:
        row, kind, seed = job.key.split("/")
        rows = by_seed.get(int(seed[len("seed"):]), {})
        if row in rows and job.key in walls:
            try:
                cost = training_cost("chain", job.config.to_dict())
            except hnn.DivergenceError as err:      # a black-box L's first steps can meet a singular d2L/dqdot2
                print(f"peers: {job.key} not timed: its timing burst failed in training ({type(err).__name__}: "
                      f"{str(err).split(':')[0]}); its wall time, {walls[job.key]:.0f} s, is in the record", flush=True)
                continue
            rows[row].setdefault("seconds", {})[kind] = {**cost, "wall": walls[job.key]}
    for rows in by_seed.values():
        for entries in rows.values():
            entries.setdefault("seconds", {})
    return by_seed


def curves_figure(found: dict, path: Path, seed: int = 0) -> Path:
    """docs/figures/peers-curves.png: one panel per protocol row, the held-out loss of each kind (log axis),
    of the runs of ``seed``."""
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
    # three lines: as one, the label ran past the figure's top and bottom
    axes[0][0].set_ylabel("held-out loss\n(snippet MAE; LNN: dx/dt MSE,\nits lagrangian kind L1)", fontsize=8)
    axes[0][-1].legend(fontsize=7)
    fig.suptitle(f"Training curves of seed {seed}'s runs", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)


def over_seeds(by_seed: dict) -> dict:
    """The rows of several seeds (``{seed: measure(...)}``) as one: per kind the mean over the seeds of each
    seed's mean error, ``seeds`` (each seed's mean, in seed order), ``low``/``high`` (their range) and ``se``
    (their standard error), the median of the seeds' medians, and ``failed`` (``{seed: why}``: "blew up: ..."
    or "failed in training: ..."); a kind no seed measured keeps the first seed's failure, and ``failed``. The chaos floor is the
    first seed's (the same starts); the training seconds are ``cost_over_seeds``."""
    first = by_seed[min(by_seed)]
    out = {}
    for row, entries in first.items():
        merged = {"floor": entries.get("floor"),
                  "seconds": cost_over_seeds([rows[row].get("seconds", {}) for rows in by_seed.values()])}
        kinds = {k for rows in by_seed.values() for k in rows[row] if k not in ("floor", "seconds")}
        for kind in sorted(kinds):
            found = {seed: rows[row].get(kind) for seed, rows in sorted(by_seed.items())}
            means = {seed: e["mean"] for seed, e in found.items() if e and "mean" in e}
            failed = {seed: f"blew up: {e['blew_up']}" if "blew_up" in e else f"failed in training: {e['diverged']}"
                      for seed, e in found.items() if e and "mean" not in e}
            if not means:       # the first seed's failure, and every seed's
                merged[kind] = {**next(e for e in found.values() if e), "failed": failed}
                continue
            values = np.array(list(means.values()))
            merged[kind] = {"mean": float(values.mean()), "seeds": [float(v) for v in values],
                            "low": float(values.min()), "high": float(values.max()),
                            "se": float(values.std(ddof=1) / np.sqrt(len(values))) if len(values) > 1 else 0.0,
                            "median": float(np.median([found[s]["median"] for s in means])),
                            "n": found[next(iter(means))]["n"], "failed": failed}
        out[row] = merged
    return out


def cost_over_seeds(costs: list[dict]) -> dict:
    """Each kind's training cost over its seeds' runs (``costs``: each seed's ``{kind: {steps_per_s, steps,
    seconds, wall}}``, the same config but the seed): ``seconds`` and ``steps_per_s`` the median of the seeds'
    timings, ``low``/``high`` their range (how far one timing moves between runs), ``walls`` every run's
    recorded wall time."""
    out = {}
    for kind in dict.fromkeys(kind for cost in costs for kind in cost):
        found = [cost[kind] for cost in costs if kind in cost]
        seconds = [entry["seconds"] for entry in found]
        out[kind] = {"seconds": float(np.median(seconds)), "low": min(seconds), "high": max(seconds),
                     "steps_per_s": float(np.median([entry["steps_per_s"] for entry in found])),
                     "steps": found[0]["steps"], "walls": [entry.get("wall") for entry in found]}
    return out
