"""The peers' record: each trained run's measured numbers, kept where a table trained over several
sittings or machines outlives its run folders (the full table's: ``docs/peers-runs.json``, committed).

A run's checkpoint is what its numbers are measured from; the record keeps those numbers, keyed by the
run's name (``chain<N>/<kind>/seed<S>``, ``lnn/<kind>/seed<S>``) and its config's identity
(``RunConfig.key``): its protocol's entry (``{mean, median, n}``, ``{"blew_up": why}`` or
``{"diverged": why}``), its recorded wall time, the seconds its measuring took and its held-out loss
curve, with each row's chaos floor
and the measuring settings. A run recorded under the same identity is neither trained nor measured
again, even where its folder is gone; one whose config changed is recorded again. The table is built
from the record (``by_seed``), with each kind's training cost timed at that point (``peer_measure``).
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import json
import multiprocessing
import statistics
import time
from pathlib import Path

from hnn.sweeps import sweep
from hnn_analysis import plan
from hnn.io import atomic_write
from hnn.threads import torch_threads
from hnn_analysis.chains.peer_measure import diverged_entry, measure, one_thread
from hnn_analysis.chains.peer_plan import FULL_SEEDS, QUICK_COSTS, plan_seeds, quick_measuring

RECORD = Path("docs") / "peers-runs.json"
# what a run's numbers depend on beyond its config: a record measured with other settings is another table
MEASURING = ("test_starts", "lnn_starts", "max_iterations", "lnn_horizon")


def measuring(settings: dict) -> dict:
    """The settings a run's recorded numbers were measured with."""
    return {name: settings.get(name) for name in MEASURING}


def load(path: Path, settings: dict) -> dict:
    """The record at ``path`` (an empty one where there is none). Raises ``ValueError`` naming the fix
    when it cannot be read or was measured with other settings than ``settings``."""
    fresh = {"measuring": measuring(settings), "floors": {}, "runs": {}}
    try:
        record = json.loads(Path(path).read_text())
    except FileNotFoundError:
        return fresh
    except (OSError, ValueError) as err:
        raise ValueError(f"the peers' record {path} cannot be read ({err}): restore it (git checkout {path}), "
                         "or pass --record with a new path to start another") from err
    if not isinstance(record, dict) or not {"measuring", "floors", "runs"} <= set(record):
        raise ValueError(f"{path} is not a peers' record (no measuring, floors and runs): pass --record with "
                         "another path")
    if record["measuring"] != fresh["measuring"]:
        raise ValueError(f"the peers' record {path} was measured with {record['measuring']}, this table "
                         f"measures with {fresh['measuring']}: pass --record with another path")
    return record


def save(path: Path, record: dict) -> None:
    """``record`` at ``path``, atomically, one run a line (a sitting's new runs are its diff)."""
    runs = ",\n".join(f"    {json.dumps(key)}: {json.dumps(entry, separators=(',', ':'))}"
                      for key, entry in sorted(record["runs"].items()))
    text = ("{\n" + f'  "measuring": {json.dumps(record["measuring"])},\n'
            + f'  "floors": {json.dumps(record["floors"], sort_keys=True)},\n'
            + '  "runs": {' + ("\n" + runs + "\n  " if runs else "") + "}\n}\n")
    atomic_write(path, lambda tmp: Path(tmp).write_text(text))


def recorded(record: dict, job: sweep.Job) -> dict | None:
    """``job``'s entry in ``record``, or None (not recorded, or recorded for another config)."""
    entry = record["runs"].get(job.key)
    return entry if entry is not None and entry["identity"] == job.config.key() else None


def _curve(folder: Path) -> dict:
    history = json.loads((folder / "metrics.json").read_text())["history"]
    return {"steps": history["test_steps"], "loss": [float(f"{v:.4g}") for v in history["test_loss"]]}


def _wall(folder: Path) -> float | None:
    return json.loads((folder / "metrics.json").read_text()).get("train_seconds")


def _settings_for(settings: dict, keys) -> dict:
    """``settings`` cut to the rows of ``keys``: no chaos floor or truth is computed for a row with nothing to measure."""
    rows = {key.split("/")[0] for key in keys}
    return {**settings, "bobs": tuple(n for n in settings["bobs"] if f"chain{n}" in rows),
            "lnn_starts": settings["lnn_starts"] if "lnn" in rows else 0}


def _add(record: dict, rows: dict, jobs: dict, runs: dict, seed: int, seconds: float) -> list[str]:
    """Put seed ``seed``'s measured ``rows`` into ``record``, each run with its share of the ``seconds``
    they took to measure; the keys it added."""
    keys = [f"{row}/{kind}/seed{seed}" for row, entries in rows.items() for kind in entries]
    keys = [key for key in keys if key in jobs]
    measured = sum(isinstance(runs.get(key), Path) for key in keys)
    for key in keys:
        row, kind, _ = key.split("/")
        folder = runs.get(key)
        saved = isinstance(folder, Path)
        record["runs"][key] = {"identity": jobs[key].config.key(), "entry": rows[row][kind],
                               "wall": _wall(folder) if saved else None,
                               "measuring": round(seconds / measured, 1) if saved else None,
                               "curve": _curve(folder) if saved else None}
    for row, entries in rows.items():
        if "floor" in entries:
            record["floors"].setdefault(row, entries["floor"])
    return keys


def _measure(runs: dict, settings: dict, seed: int) -> tuple[dict, float]:
    """``peer_measure.measure`` and the seconds it took."""
    tic = time.perf_counter()
    rows = measure(runs, settings, seed)
    return rows, time.perf_counter() - tic


def record_runs(runs: dict, jobs: list[sweep.Job], settings: dict, path: Path, n_jobs: int = 1) -> dict:
    """Measure every run of ``runs`` (``{key: run folder or sweep.RunFailed}``) that ``path``'s record
    lacks, add it, and return the record. A run that failed in training is recorded as such (its
    ``diverged`` entry); one that failed otherwise is not recorded (it trains again). Each seed is measured
    here, or in one of ``n_jobs`` worker processes of one torch thread, and the record is rewritten
    after each seed, so a killed measuring keeps every seed it finished."""
    record = load(path, settings)
    by_key = {job.key: job for job in jobs}
    todo = {key: outcome for key, outcome in runs.items()
            if key in by_key and recorded(record, by_key[key]) is None
            and (isinstance(outcome, Path) or (isinstance(outcome, sweep.RunFailed) and outcome.diverged))}
    seeds = sorted({int(key.rsplit("seed", 1)[1]) for key in todo})
    if not todo:
        return record
    print(f"peers: recording {len(todo)} run{'' if len(todo) == 1 else 's'} in {path}", flush=True)

    def keys_of(seed: int) -> dict:      # the saved runs: a worker gets their folders, the failures stay here
        return {key: folder for key, folder in todo.items() if key.endswith(f"/seed{seed}") and isinstance(folder, Path)}

    def done(seed: int, rows: dict, seconds: float) -> None:
        for key, err in todo.items():
            row, kind, run_seed = key.split("/")
            if run_seed == f"seed{seed}" and isinstance(err, sweep.RunFailed):
                rows.setdefault(row, {})[kind] = diverged_entry(err)
        added = _add(record, rows, by_key, todo, seed, seconds)
        save(path, record)
        print(f"peers: seed {seed}: {len(added)} run{'' if len(added) == 1 else 's'} recorded", flush=True)

    if n_jobs <= 1 or len(seeds) < 2:
        for seed in seeds:
            done(seed, *_measure(keys_of(seed), _settings_for(settings, keys_of(seed)), seed))
        return record
    context = multiprocessing.get_context("spawn")     # a fresh interpreter: no torch state copied by fork
    with concurrent.futures.ProcessPoolExecutor(min(n_jobs, len(seeds)), mp_context=context,
                                                initializer=one_thread) as pool:
        futures = {pool.submit(_measure, keys_of(seed), _settings_for(settings, keys_of(seed)), seed): seed
                   for seed in seeds}
        for future in concurrent.futures.as_completed(futures):
            done(futures[future], *future.result())
    return record


def by_seed(record: dict, jobs: list[sweep.Job], settings: dict, seeds) -> dict:
    """``{seed: {row: {"floor", kind: entry}}}`` of ``jobs``' recorded runs, as ``peer_measure.measure``
    gives them (without ``seconds``); a row with no recorded run is left out."""
    out = {seed: {} for seed in seeds}
    for job in jobs:
        entry = recorded(record, job)
        if entry is None:
            continue
        row, kind, seed = job.key.split("/")
        rows = out[int(seed[len("seed"):])]
        rows.setdefault(row, {"floor": record["floors"].get(row)})[kind] = entry["entry"]
    order = [f"chain{n}" for n in settings["bobs"]] + ["lnn"]
    return {seed: {row: rows[row] for row in order if row in rows} for seed, rows in out.items()}


def curves(record: dict, jobs: list[sweep.Job], seed: int) -> dict:
    """Seed ``seed``'s held-out loss curves ``{row: {kind: {"epochs", "test_loss"}}}``: x in CHNN's epochs
    of 800 snippets (4 steps of batch 200) for the chain rows, in steps for the LNN row."""
    out = {}
    for job in jobs:
        entry = recorded(record, job)
        row, kind, run_seed = job.key.split("/")
        if entry is None or entry["curve"] is None or run_seed != f"seed{seed}":
            continue
        per_epoch = 1.0 if row == "lnn" else 800 / 200
        out.setdefault(row, {})[kind] = {"epochs": [step / per_epoch for step in entry["curve"]["steps"]],
                                         "test_loss": entry["curve"]["loss"]}
    return out


def walls(record: dict, jobs: list[sweep.Job]) -> dict:
    """``{key: recorded training wall time in s}`` of ``jobs``' recorded saved runs."""
    return {job.key: entry["wall"] for job in jobs if (entry := recorded(record, job)) is not None and entry["wall"]}


def keeper(jobs: list[sweep.Job], settings: dict, path: Path):
    """A sweep's ``on_done``: each run into the record as it finishes (a lost sitting keeps it), measured
    on one thread while the workers train on."""
    def keep(job: sweep.Job, outcome) -> None:
        with torch_threads(1):
            record_runs({job.key: outcome}, jobs, settings, path)
    return keep


def with_expected_seconds(record: dict, jobs: list[sweep.Job], known: list[sweep.Job]) -> list[sweep.Job]:
    """``jobs``, each with its ``expected_seconds`` where ``known``'s recorded runs give them (``expected_seconds``)."""
    hints = expected_seconds(record, jobs, known)
    return [dataclasses.replace(job, expected_seconds=hints.get(job.key)) for job in jobs]


def expected_seconds(record: dict, jobs: list[sweep.Job], known: list[sweep.Job]) -> dict:
    """``{key: seconds}``: each of ``jobs``' expected training time, for the sweep's longest-first order
    (every chain run is one task of the same steps to the sweep's own estimate): the median recorded
    wall time per step of ``known``'s runs of its row and kind (other seeds), else of its kind on its
    protocol's other rows (a step of a kind costs about the same at every N on the chain, docs/peers.md),
    times its steps. A job with neither is left out."""
    rates = {}
    for job in known:
        if (entry := recorded(record, job)) is not None and entry["wall"]:
            row, kind, _ = job.key.split("/")
            rates.setdefault((row, kind), []).append(entry["wall"] / job.steps)
    out = {}
    for job in jobs:
        row, kind, _ = job.key.split("/")
        same = rates.get((row, kind)) or [rate for (other, other_kind), kind_rates in rates.items()
                                          if other_kind == kind and (other == "lnn") == (row == "lnn")
                                          for rate in kind_rates]
        if same:
            out[job.key] = statistics.median(same) * job.steps
    return out


def measuring_seconds(record: dict, jobs: list[sweep.Job]) -> float:
    """The seconds that measuring ``jobs``' recorded runs took, in all (whatever sittings measured them)."""
    return sum(entry.get("measuring") or 0.0 for job in jobs if (entry := recorded(record, job)) is not None)


def plan_sitting(record: dict, todo: list[sweep.Job], fresh: list[sweep.Job], runs: dict, settings: dict, out,
                 seeds: range, workers: int, quick: bool = False, table: bool = True) -> list[sweep.Job]:
    """``todo`` timed, longest first by the recorded runs of each kind at every seed of the plan
    (``with_expected_seconds``), the rest measured now (``analysis/plan.py``), after printing the sitting's plan:
    training them on ``workers``, then measuring the ``fresh`` runs that did not fail (``runs``) at the record's
    per-run costs of their kinds, and timing the kinds for the ``table`` (not with --train-only); ``quick``
    (``--quick``'s own settings): a measuring that the record cannot price, and the timing, at their declared
    costs (``peer_plan.QUICK_COSTS``)."""
    known = plan_seeds(settings, out, range(max(FULL_SEEDS, seeds.stop)))
    todo = plan.timed(with_expected_seconds(record, todo, known))
    measured = [job for job in fresh if not isinstance(runs.get(job.key), sweep.RunFailed)]
    measuring, how = expected_measuring(record, measured, known), "the record's median a run of its kind"
    if measuring is None and quick:     # a fresh --quick: no run of its kinds recorded yet
        measuring, how = sum(map(quick_measuring, measured)), "each run's declared measuring by its bobs"
    timing = [plan.Stage("time", len(settings["kinds"]), "kinds", QUICK_COSTS["timing"] if quick else None,
                         "the table's one-thread rates, declared")] if table else []
    plan.say("peers", [plan.training(todo, workers),
                       plan.Stage("measure", len(measured), "runs' rollouts (each as it finishes training)",
                                  measuring, how), *timing])
    return todo


def expected_measuring(record: dict, jobs: list[sweep.Job], known: list[sweep.Job]) -> float | None:
    """The seconds of measuring ``jobs``' runs (their rollouts, as each finishes): each the median recorded
    measuring time of ``known``'s recorded runs of its kind (any row), None where no run of a kind is recorded."""
    times = {}
    for job in known:
        if (entry := recorded(record, job)) is not None and entry.get("measuring"):
            times.setdefault(job.key.split("/")[1], []).append(entry["measuring"])
    kinds = [job.key.split("/")[1] for job in jobs]
    if any(kind not in times for kind in kinds):
        return None
    return sum(statistics.median(times[kind]) for kind in kinds)
