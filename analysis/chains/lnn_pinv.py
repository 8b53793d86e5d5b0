"""The LNN solved as its authors solve it (``--lnn_solve pinv``) on the peers' runs that stopped with a singular
d2L/dqdot2 (``analysis/stress.py --lnn-pinv``): each run of the peers' record that failed with a
``SingularLagrangianError`` under the plain solve (``PLAIN_STOPS``) trains again, its config the peers' table's but for the solve, up to ``past`` steps
beyond the step where it stopped (its cosine schedule still that of its 8000 steps), and this counts the
training states whose qddot came from the pseudo-inverse, the steps that had any, and the loss around them."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path


import hnn
from hnn.threads import torch_threads
from hnn_analysis import pages
from hnn_analysis.chains import peer_plan
from hnn_analysis.commands import run_tasks
from hnn_analysis.provenance import machine

class _Enough(Exception):
    """Raised by the progress callback once the run has trained the steps it was given."""


# the LNN runs of the peers' table that stopped with a singular d2L/dqdot2 under the plain solve (CHNN's chains
# and the LNN protocol, of 8000 and 60000 steps), and the training step where each stopped: docs/peers-runs.json at commit 3d4248d (its "diverged" entries), whose
# lagrangian entries left the record when the table chose the pseudo-inverse (their configs are no longer
# the table's)
PLAIN_STOPS = {"chain2/lagrangian/seed0": 1846, "chain2/lagrangian/seed2": 374, "chain2/lagrangian/seed3": 371,
               "chain3/lagrangian/seed1": 1648, "chain3/lagrangian/seed2": 1143, "chain3/lagrangian/seed3": 1474,
               "chain3/lagrangian/seed4": 676, "chain5/lagrangian/seed0": 1104, "chain5/lagrangian/seed1": 144,
               "chain5/lagrangian/seed2": 183, "chain5/lagrangian/seed3": 1624, "chain5/lagrangian/seed4": 146,
               "lnn/lagrangian/seed4": 20612}


def _job(key: str, save_dir: Path, solve: str = "pinv") -> hnn.sweeps.sweep.Job:
    """The peers' table's job of ``key`` (``chain<N>/lagrangian/seed<S>``), with the ``solve`` of qddot."""
    seed = int(key.rsplit("seed", 1)[1])
    settings = {"kinds": ("lagrangian",), **peer_plan.FULL}
    job = next(job for job in peer_plan.plan(settings, save_dir, seed) if job.key == key)
    return dataclasses.replace(job, config=dataclasses.replace(job.config, lnn_solve=solve))


@torch_threads(1)       # one torch thread, the caller's count back after (it also runs in-process)
def train_past(key: str, stopped: int, past: int, save_dir: Path, solve: str = "pinv") -> dict:
    """Train the run ``key`` with the pseudo-inverse solve as ``hnn.run_experiment`` trains it (its seed's init,
    data, minibatches and schedule; no test batch, which draws from its own generator) for ``stopped + past``
    steps, or to its end; per step the training states solved by the pseudo-inverse. ``solve='solve'``: the
    plain solve instead, to check that a recorded stop repeats on this machine. A worker's task."""
    config = _job(key, save_dir, solve).config
    prep = hnn.prepare(config)      # the run's init, data, units, balance and rows, as hnn.run_experiment's
    if prep.scales is not None:
        raise ValueError(f"{key}: --units auto rescales this run's data, which the peers' runs did not")
    model, options = prep.canonical_model, prep.options
    limit = min(stopped + past, config.total_steps + 1)
    counts, losses, last = [], [], {}
    batch_loss = options.loss_of(model)     # a fit of dx/dt (the LNN protocol): the loss hnn.train builds

    def loss(xb, yb):           # the objective's loss, its training batches' mean kept (no number changes)
        out = batch_loss(xb, yb)
        last["value"] = float(out.detach().mean())
        return out

    def count(done: int, total: int) -> None:
        counts.append(model.pinv_states - sum(counts))
        losses.append(last.get("value"))
        if done >= limit:
            raise _Enough
    row = {"key": key, "stopped": stopped, "limit": limit, "total_steps": config.total_steps}
    tic = time.perf_counter()
    try:
        # no test batch: its forward passes would add pseudo-inverse states to the steps' counts
        hnn.trainers.lone.train_prepared(dataclasses.replace(prep, test_x=None, test_y=None), on_step=count, loss=loss)
    except _Enough:
        pass
    except hnn.DivergenceError as err:
        row["stop"] = f"{type(err).__name__}: {str(err)[:200]}"
        # the step that failed: the states its pseudo-inverse took before the failure (no callback ran)
        row["pinv_at_stop"] = model.pinv_states - sum(counts)
    row["seconds"] = time.perf_counter() - tic
    row["steps"] = len(counts)
    row["pinv_per_step"], row["loss"] = counts, losses
    return row


def summary(row: dict) -> dict:
    """What a row says: the first step with a pseudo-inverse state, the steps and states that had one (the
    step that failed included), and how many steps it trained past the step where the plain solve stopped."""
    counts = row["pinv_per_step"] + ([row["pinv_at_stop"]] if row.get("pinv_at_stop") is not None else [])
    steps_with = [i for i, c in enumerate(counts) if c]
    return {"first": steps_with[0] if steps_with else None, "steps_with": len(steps_with), "states": sum(counts),
            "past": max(0, row["steps"] - row["stopped"])}


def lnn_pinv_text(rows: list[dict], meta: dict, past: int) -> str:
    """The section's table: one line per run."""
    jobs = f"{meta['jobs']} processes of one torch thread" if meta.get("jobs", 1) > 1 else "one torch thread"
    lines = [pages.generated_by(meta, f"{machine(meta)}, {jobs}") + ", "
             f"{meta['seconds']:.0f} s wall, {meta['cpu_seconds']:.0f} s of CPU: each LNN run of the peers' table "
             f"(docs/peers-runs.json) that stopped with a singular d2L/dqdot2, trained again as that table trains it "
             f"but with --lnn_solve pinv, to {past} steps past the step where it stopped (its cosine schedule still "
             "its 8000 steps'); the training states whose qddot came from the pseudo-inverse, per run.", "",
             "| run | plain solve stopped at step | first step with a pinv state | steps with one | pinv states "
             "| steps trained past the stop | seconds a step | outcome |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for row in rows:
        s = summary(row)
        outcome = row.get("stop", f"trained to step {row['steps'] - 1} of {row['total_steps']}")
        lines.append(f"| {row['key']} | {row['stopped']} | {s['first'] if s['first'] is not None else '-'} | "
                     f"{s['steps_with']} | {s['states']} | {s['past']} | {row['seconds'] / max(row['steps'], 1):.2f} | "
                     f"{outcome} |")
    return "\n".join(lines) + "\n"


def measure(keys: list[str] | None, past: int, save_dir: Path, jobs: int) -> list[dict]:
    """``train_past`` of the stopped runs ``keys`` (None: every one), each a worker's task; ValueError naming
    the stopped runs for a key that is not one."""
    stopped = PLAIN_STOPS
    keys = keys or list(stopped)
    unknown = [key for key in keys if key not in stopped]
    if unknown:
        raise ValueError(f"--lnn-runs {' '.join(unknown)}: not a run of the peers' table that stopped with a "
                         f"singular d2L/dqdot2 under the plain solve; those are {', '.join(stopped)}")
    tasks = [(train_past, (key, stopped[key], past, save_dir)) for key in keys]
    return run_tasks(tasks, jobs, lambda task: task[1][0])


def pinv_results_text(results: dict) -> str:
    return lnn_pinv_text(results["lnn_pinv"], results["meta"], results["past"])


def pinv_seeds(results: dict) -> pages.Seeds:
    """Each row's runs are the peers' seeds that stopped: the fewest of any row."""
    keys = [row["key"] for row in results["lnn_pinv"]]
    fewest = min(sum(key.startswith(row + "/") for key in keys) for row in {key.split("/")[0] for key in keys})
    return pages.Seeds(fewest, None if fewest >= pages.MIN_SEEDS else
                       "each row holds the seeds of the peers' table that stopped with a singular d2L/dqdot2 (those "
                       "run here: --lnn-runs), each its own run: counts, not a spread")
