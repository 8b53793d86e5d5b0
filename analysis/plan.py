"""What a study will cost, said before it starts: its stages, each with a count and an estimate from measured
per-run costs, and the total on this box.

    jobs = plan.timed(jobs)                                  # each run's training, measured now
    plan.say("reproduce", [plan.training(jobs, 2), plan.Stage("evaluate", 7, "rows")], jobs=2)

A run's training estimate is its steps at the rate of that config alone on one thread over a short burst
(``training_cost``, once a config, seeds aside), or for a least-squares fit its solve on two slices of its
rows, timed and drawn out to all of them (``fit_seconds``), and what a run costs beside its steps
(``overhead``: a one-step run of its task, timed once), set as the job's ``expected_seconds``, so the
sweep also starts the longest first and says its time left at the rate the estimates run at
(``hnn.sweeps.sweep.train_jobs``). The runs are shared over ``--jobs`` workers longest first (``schedule``). A stage
whose cost is not known before it runs (a model's measurement) is counted and timed from its first units
(``Ahead``): its lines say the time left as it goes. The estimates are for a quiet box: the plan says the load
it saw, since two torch processes of two threads each ran up to 30x slower than one (docs/speed.md#threads).
"""
from __future__ import annotations

import dataclasses
import heapq
import importlib
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import hnn
from hnn.progress import Rate, say_left


@dataclass
class Stage:
    """One stage of a plan: ``count`` ``unit`` of ``what``, ``seconds`` its wall-time estimate (None: timed as it
    runs) and ``how`` that estimate was made; ``share``: its seconds of a quick study's budget, where it has one
    (the plan says a stage whose estimate passes it)."""
    what: str
    count: int
    unit: str
    seconds: float | None = None
    how: str = ""
    share: float | None = None

    @property
    def over(self) -> bool:
        """Whether its estimate passes its share."""
        return self.share is not None and self.seconds is not None and self.seconds > self.share


# the bursts of a plan's measurement of a config: one short one (a plan must cost little beside what it plans)
BURSTS, BURST_SECONDS = 1, 0.05
# The reference box of the quick budgets (tests/test_plan.py: a quick mode's plan within its budget there), from
# declared costs alone: a quiet 2-core box on which a task's training step costs its ``TaskSpec.cost`` (a
# full run's seconds) over its default steps (a narrower network's step in proportion to its width: mostly the
# step's fixed work, width 16 took 0.10-0.27 of width 200's step on spring, pend and 2body; a wider one's by the
# square, its products), a run REFERENCE_RUN_SECONDS beside its steps (its data read, its model built, its losses
# and folder: the quick scene study's 34 runs took 7.3 s, 3.7 s of it their steps and solves, at 1.2 load on the
# 2-core box, 2026-12-06; reproduce.py --quick's 12 runs 6.5 s, 4.4 s of them steps, at 643e3a4), and a
# least-squares fit REFERENCE_FIT_ROW_SECONDS a training row (the quick scene study's 18 fits solved their 8308
# rows in 1.19 s, 1.4e-4 s a row, the 3-body library's 500 rows 0.71 s of it: a plan prices the fits it holds,
# not each at the dearest's)
REFERENCE_RUN_SECONDS = 0.12
REFERENCE_FIT_ROW_SECONDS = 1.5e-4
# ... and a plan's own measuring (``timed``) REFERENCE_TIMING_SECONDS a config (its burst of steps, or a fit's solves
# on its probe rows) and a run beside its steps a task (``overhead``'s one-step run): reproduce.py --quick's plan
# took 3.4 s for its 12 configs of 6 tasks (its datasets' 1.6 s aside), the quick scene study's about 5 s for 34
# configs of 5 tasks, 18 of them fits (quiet 2-core box, 643e3a4)
REFERENCE_TIMING_SECONDS = 0.15
# ... and a model's field call in a rollout REFERENCE_FIELD_CALL_SECONDS, the dearest field of a quick study's (the
# 3-body library's on 2-5 states, the solver's work between calls included: 0.9 ms a call on a 2-core box at load 2;
# an MLP's 0.1-0.5 ms): a quick study's rollout budget in field calls is its seconds at this rate, so the same
# rollouts stop on every box
REFERENCE_FIELD_CALL_SECONDS = 0.5e-3


def reference_seconds(job, fit_rows: int | None = None) -> float:
    """A run's seconds on the reference box (``REFERENCE_RUN_SECONDS``...): its steps at its task's declared
    rate (scaled by its width against the task's), or a fit's ``fit_rows`` training rows (a quick study's cap:
    its rows at most)."""
    config = job.config
    if config.fit != "adam":
        if fit_rows is None:
            raise ValueError(f"{job.key}: a fit's reference seconds need its training rows (fit_rows)")
        return REFERENCE_RUN_SECONDS + REFERENCE_FIT_ROW_SECONDS * fit_rows
    default = hnn.tasks.task_config(job.task, {})
    width = config.hidden_dim / default.hidden_dim
    per_step = hnn.task_spec(job.task).cost / default.total_steps * (width if width <= 1 else width * width)
    return REFERENCE_RUN_SECONDS + per_step * (config.total_steps + 1)


def reference_timing(jobs: list) -> Stage:
    """A plan's own measuring of ``jobs`` (``timed``: once a config, a one-step run once a task trained by steps) on
    the reference box: ``REFERENCE_TIMING_SECONDS`` a config, ``REFERENCE_RUN_SECONDS`` a task."""
    configs = {_config_key(job) for job in jobs}
    tasks = {job.task for job in jobs if job.config.fit == "adam"}
    return Stage("plan", len(configs), "configs timed", REFERENCE_TIMING_SECONDS * len(configs)
                 + REFERENCE_RUN_SECONDS * len(tasks), "a short burst of each config's steps (a fit: its solves on "
                 "its probe rows) and a one-step run of each task, on the reference box")


def reference_data_seconds(tasks) -> float:
    """The seconds of building each of ``tasks``' datasets once at its --quick settings on the reference box:
    each task's declared ``TaskSpec.data_cost`` (a quick plan's own cost: its runs and its truths read them)."""
    return sum(hnn.task_spec(task).data_cost for task in sorted(set(tasks)))


# a fit's plan: its solve on its first PROBE_ROWS training rows and on twice as many, each timed on one thread:
# the design and its factoring grow with the rows, the rest (the threshold's re-solves, the neurons' draw) not
PROBE_ROWS = 128
_DATASETS: dict = {}        # this process's datasets of fit estimates, by dataset key
_FITS: dict = {}            # this process's fit estimates, by config


def fit_seconds(config) -> dict:
    """``{"seconds", "rows", "per_row", "fixed"}``: a least-squares fit's (``config.fit`` not ``'adam'``) solve
    on its ``rows`` training rows, estimated on one thread as ``fixed + per_row * rows`` from its solves on its
    first ``PROBE_ROWS`` rows (a sampled layer's width and one, where more) and on twice as many (its design and QR grow with the rows; the threshold's
    re-solves on the small factor and the draw of its neurons do not), without solving it on all of them."""
    from hnn.threads import torch_threads
    known = (type(config).__module__, config.key())
    if known not in _FITS:
        _FITS[known] = _fit_seconds(config, torch_threads)
    return _FITS[known]


def _fit_seconds(config, torch_threads) -> dict:
    key = config.dataset_key()
    if key not in _DATASETS:
        _DATASETS[key] = config.dataset()
    prep = hnn.prepare(config, _DATASETS[key])
    rows = len(prep.x)
    # at least a row a neuron: a sampled layer's factor is square in its width
    probe = max(PROBE_ROWS, getattr(config, "hidden_dim", 0) + 1)
    sizes = sorted({min(rows, probe), min(rows, 2 * probe)})

    def solved(n: int) -> float:
        model = hnn.kinds.model_from_spec(prep.specs.model, config.device)
        return hnn.fits.solve(model, prep.x[:n], prep.y[:n], **prep.specs.fit.solve_kwargs(), progress=False,
                              loss_weights=prep.options.loss_weights)["seconds"]
    package = hnn.fits.FITS[config.fit].package
    if package is not None:         # imported before the timing: a fit's first solve in a process imports it
        importlib.import_module(package)
    with torch_threads(1):
        timed = [solved(n) for n in sizes]
    if len(sizes) == 1:         # a dataset of PROBE_ROWS rows or fewer: solved whole
        return {"seconds": timed[0], "rows": rows, "per_row": 0.0, "fixed": timed[0]}
    per_row = max(timed[1] - timed[0], 0.0) / (sizes[1] - sizes[0])
    fixed = max(timed[0] - per_row * sizes[0], 0.0)
    return {"seconds": fixed + per_row * rows, "rows": rows, "per_row": per_row, "fixed": fixed}


def timed(jobs: list, cost=None, overhead_of=None) -> list:
    """``jobs`` (``hnn.sweeps.sweep.Job``), each with its ``expected_seconds`` measured: ``cost(task, args)["seconds"]``
    (default one short burst of ``training_cost``, or a fit's ``fit_seconds``), once per config whatever its
    seed, plus ``overhead_of(job)`` (default ``overhead``), once per task, of its first run trained by steps (a
    fit's estimate holds its own); a job that has one keeps it."""
    overhead_of = overhead_of or overhead
    if cost is None:
        from hnn_analysis.training_cost import training_cost

        def cost(task, args):
            if args.get("fit", "adam") != "adam":
                return fit_seconds(hnn.tasks.task_config(task, args))
            return training_cost(task, args, BURSTS, BURST_SECONDS)
    measured, overheads, out = {}, {}, []
    for job in jobs:
        if job.expected_seconds is None:
            key = _config_key(job)
            if key not in measured:
                try:
                    measured[key] = cost(job.task, {**job.config.to_dict(), "seed": 0})["seconds"]
                except Exception:       # a config whose first steps fail: its run fails (and says why) in the sweep
                    measured[key] = None
            fit = job.config.fit != "adam"
            if job.task not in overheads and not fit:      # a fit's one-step run would be its whole solve
                overheads[job.task] = overhead_of(job) if measured[key] is not None else 0.0
            seconds = None if measured[key] is None else measured[key] + overheads.get(job.task, 0.0)
            job = dataclasses.replace(job, expected_seconds=seconds)
        out.append(job)
    return out


def _config_key(job) -> tuple:
    """What a plan measures once: ``job``'s task and config, its seed and folder aside."""
    args = {**job.config.to_dict(), "seed": 0}
    return job.task, tuple(sorted((k, repr(v)) for k, v in args.items() if k != "save_dir"))


def overhead(job) -> float:
    """A run's seconds beside its steps (its data prepared, its model built, its final losses, its folder
    saved): a run of ``job``'s config of one step, in a folder of its own, timed (0 where it fails); for the
    short runs of a quick study this is most of a run."""
    from hnn.threads import torch_threads
    with tempfile.TemporaryDirectory(prefix="plan-") as tmp, torch_threads(1):
        # its datasets as the run will read them, from the caches in its folder (a linked file, not a copy):
        # built again there, the pixel task's frames took 20 s of a 90 s quick budget
        for cached in Path(job.config.save_dir).glob("*.npz"):
            (Path(tmp) / cached.name).symlink_to(cached.resolve())
        tic = time.perf_counter()
        try:
            hnn.run_experiment(dataclasses.replace(job.config, total_steps=0, save_dir=tmp))
        except Exception:       # its run fails (and says why) in the sweep
            return 0.0
        return time.perf_counter() - tic


def schedule(seconds: list[float], workers: int) -> float:
    """The wall time of tasks of ``seconds`` on ``workers`` workers, the longest first, each to the first free worker."""
    free = [0.0] * max(1, workers)
    for s in sorted(seconds, reverse=True):
        heapq.heapreplace(free, free[0] + s)
    return max(free)


def training(jobs: list, workers: int, share: float | None = None, how: str | None = None) -> Stage:
    """The training stage of ``jobs`` (``timed`` ones) on ``workers`` processes (``share``: its seconds of a
    quick study's budget); its ``how`` (default: measured now) names the fits (least-squares solves) among them
    and their estimate."""
    seconds = [job.expected_seconds or 0.0 for job in jobs]
    untimed = sum(job.expected_seconds is None for job in jobs)
    fits = [job.expected_seconds or 0.0 for job in jobs if job.config.fit != "adam"]
    return Stage("train", len(jobs), "run" if len(jobs) == 1 else "runs", schedule(seconds, workers) if jobs else 0.0,
                 (how or "each run's steps at its config's one-thread rate, measured now")
                 + (f"; {len(fits)} least-squares fits at about {sum(fits):.2g} s" + ("" if how else
                    f", drawn out from their solves on {PROBE_ROWS} and {2 * PROBE_ROWS} rows") if fits else "")
                 + (f", on {workers} processes" if workers > 1 and len(jobs) > 1 else "")
                 + (f"; {untimed} could not be timed" if untimed else ""), share)


def _words(seconds: float) -> str:
    return say_left(seconds).replace(" left", "")


def say(who: str, stages: list[Stage]) -> str:
    """Print the plan, one line a stage and the total, before the study starts; returns it."""
    known = [s.seconds for s in stages if s.seconds is not None]
    lines = [f"{who}: plan on this box ({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} now; other jobs on it "
             "slow every stage):"]
    for s in stages:
        estimate = ("timed as it runs, from its first units" if s.seconds is None else _words(s.seconds))
        lines.append(f"  {s.what} {s.count} {s.unit}: {estimate}" + (f" ({s.how})" if s.how and s.seconds else "")
                     + (f"; OVER its share of {s.share:g} s" if s.over else f"; its share {s.share:g} s"
                        if s.share is not None else ""))
    if known:
        rest = " and the stages timed as they run" if len(known) < len(stages) else ""
        lines.append(f"  in all: {_words(sum(known))}{rest}")
    text = "\n".join(lines)
    print(text, flush=True)
    return text


class Ahead:
    """The time left of a stage of ``total`` units of work (``weight`` of each unit, default 1) at the rate of
    the recent past: ``tag(done_weight)`` after each unit gives ``', about 3 min left'`` (nothing before a rate)."""

    def __init__(self, total: float):
        self.total, self.rate = total, Rate(0.0, time.perf_counter())

    def tag(self, done: float) -> str:
        self.rate.add(done)
        left = self.rate.left(self.total)
        return "" if left is None or done >= self.total else f", {say_left(left)}"
